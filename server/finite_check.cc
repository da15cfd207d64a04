#include "server/finite_check.h"

#include <cmath>
#include <string>
#include <vector>

#include <google/protobuf/descriptor.h>

#include "absl/strings/str_cat.h"

namespace dynsolid::server {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using google::protobuf::Reflection;

std::string Join(absl::string_view prefix, absl::string_view name) {
  return prefix.empty() ? std::string(name) : absl::StrCat(prefix, ".", name);
}

absl::Status NotFinite(const std::string& path, double value) {
  return absl::InvalidArgumentError(absl::StrCat(path, ": must be finite, got ", value));
}

absl::Status Walk(const Message& m, const std::string& prefix) {
  const Reflection* r = m.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  r->ListFields(m, &fields);  // set fields only, in field-number order
  for (const FieldDescriptor* f : fields) {
    const std::string path = Join(prefix, f->name());
    if (f->is_repeated()) {
      const int n = r->FieldSize(m, f);
      for (int i = 0; i < n; ++i) {
        const std::string item = absl::StrCat(path, "[", i, "]");
        switch (f->cpp_type()) {
          case FieldDescriptor::CPPTYPE_DOUBLE: {
            const double v = r->GetRepeatedDouble(m, f, i);
            if (!std::isfinite(v)) return NotFinite(item, v);
            break;
          }
          case FieldDescriptor::CPPTYPE_FLOAT: {
            const float v = r->GetRepeatedFloat(m, f, i);
            if (!std::isfinite(v)) return NotFinite(item, v);
            break;
          }
          case FieldDescriptor::CPPTYPE_MESSAGE: {
            absl::Status s = Walk(r->GetRepeatedMessage(m, f, i), item);
            if (!s.ok()) return s;
            break;
          }
          default:
            break;
        }
      }
      continue;
    }
    switch (f->cpp_type()) {
      case FieldDescriptor::CPPTYPE_DOUBLE: {
        const double v = r->GetDouble(m, f);
        if (!std::isfinite(v)) return NotFinite(path, v);
        break;
      }
      case FieldDescriptor::CPPTYPE_FLOAT: {
        const float v = r->GetFloat(m, f);
        if (!std::isfinite(v)) return NotFinite(path, v);
        break;
      }
      case FieldDescriptor::CPPTYPE_MESSAGE: {
        absl::Status s = Walk(r->GetMessage(m, f), path);
        if (!s.ok()) return s;
        break;
      }
      default:
        break;
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckFinite(const Message& message, absl::string_view prefix) {
  return Walk(message, std::string(prefix));
}

}  // namespace dynsolid::server
