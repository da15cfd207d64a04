// A fresh directory under the test temp dir, removed with everything in it
// at the end of its scope.
#pragma once

#include <stdlib.h>

#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"

namespace dynsolid::testing {

class TempDir {
 public:
  // The directory is named `prefix` and six random characters.
  explicit TempDir(const std::string& prefix) {
    std::string t = ::testing::TempDir() + prefix + "_XXXXXX";
    path_ = ::mkdtemp(t.data());
  }
  ~TempDir() { std::system(absl::StrCat("rm -rf '", path_, "'").c_str()); }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

}  // namespace dynsolid::testing
