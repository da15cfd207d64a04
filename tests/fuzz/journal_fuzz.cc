// Fuzzes the journal reader (server/journal.h ReadJournal, which reads a
// path: each input is written to a temporary file of this process) and
// the first things recovery (server/persistence.cc RecoverSession) does with
// each record: parse the payload as a persist::JournalRecord and check its
// command's numbers (scene::ValidateValues, what SimCore::Apply does first).
// Applying commands is the command target's business. Links journal.cc and
// the scene library, not the server.
//
// Input: the first byte is a mode, the rest the journal.
//   mode & 1: the rest is 2-byte-length-prefixed chunks (fuzz_util.h), each
//             framed with a valid CRC (FrameRecord), so the fuzzer reaches
//             the records' contents; otherwise the rest is the file as is.
//   mode & 2: read from byte offset mode >> 2 (a snapshot's offset),
//             otherwise from 0.
// Invariants: no crash or sanitizer report; the records and their headers
// account for exactly [offset, valid_end); valid_end <= file_bytes, and a
// tail problem is reported exactly when valid_end < file_bytes.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <google/protobuf/text_format.h>

#include "dynsolid/journal.pb.h"
#include "server/journal.h"
#include "solver/scene/scene_loader.h"
#include "tests/fuzz/fuzz_proto.h"
#include "tests/fuzz/fuzz_util.h"

namespace {

namespace fz = dynsolid::fuzz;

std::string Record(int64_t step, const char* client, uint64_t seq, const char* command) {
  dynsolid::persist::JournalRecord r;
  r.set_step(step);
  r.set_client_id(client);
  r.set_seq(seq);
  if (!google::protobuf::TextFormat::ParseFromString(command, r.mutable_command())) std::abort();
  return r.SerializeAsString();
}

void WriteSeeds(const std::string& dir) {
  const std::vector<std::string> records = {
      Record(0, "c", 1, "set_gravity { z: -9.81 }"),
      Record(2, "c", 2, "add_point_force { position { x: 1.5 y: 1.5 z: 3 } force { z: -1 } }"),
      Record(3, "c", 3, "pause {}"),
      Record(3, "d", 1, "step { count: 2 }"),
  };
  std::string file;
  for (const std::string& r : records) file += dynsolid::server::FrameRecord(r);
  // The file as on disk, a torn copy, and the records for framed mode.
  fz::WriteFile(dir + "/raw", std::string(1, '\0') + file);
  fz::WriteFile(dir + "/raw_torn", std::string(1, '\0') + file.substr(0, file.size() - 5));
  fz::WriteFile(dir + "/framed", std::string(1, '\1') + fz::JoinChunks(records));
  const size_t first = dynsolid::server::FrameRecord(records[0]).size();
  fz::WriteFile(dir + "/raw_from_offset",
                std::string(1, static_cast<char>(2 | (first << 2))) + file);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  dynsolid::fuzz::QuietProtobuf();
  const std::string dir = fz::SeedDir();
  if (!dir.empty()) {
    WriteSeeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const uint8_t mode = data[0];
  const std::string_view rest(reinterpret_cast<const char*>(data) + 1, size - 1);
  std::string file;
  if (mode & 1) {
    for (std::string_view chunk : fz::SplitChunks(rest)) {
      file += dynsolid::server::FrameRecord(absl::string_view(chunk.data(), chunk.size()));
    }
  } else {
    file.assign(rest);
  }
  const uint64_t offset = (mode & 2) ? (mode >> 2) : 0;
  static const std::string path = fz::TempPath(".journal");
  fz::WriteFile(path, file);

  absl::StatusOr<dynsolid::server::JournalContents> c = dynsolid::server::ReadJournal(path, offset);
  if (!c.ok()) {
    FUZZ_CHECK(offset > file.size(), "ReadJournal failed: %s",
               std::string(c.status().message()).c_str());
    return 0;
  }
  FUZZ_CHECK(c->file_bytes == file.size(), "file_bytes %llu, wrote %zu",
             static_cast<unsigned long long>(c->file_bytes), file.size());
  uint64_t end = offset;
  for (const std::string& r : c->records) end += 8 + r.size();
  FUZZ_CHECK(end == c->valid_end, "records end at %llu, valid_end %llu",
             static_cast<unsigned long long>(end), static_cast<unsigned long long>(c->valid_end));
  FUZZ_CHECK(c->valid_end <= c->file_bytes, "valid_end past the end of the file");
  FUZZ_CHECK(c->tail_problem.empty() == (c->valid_end == c->file_bytes),
             "tail_problem \"%s\" with valid_end %llu of %llu", c->tail_problem.c_str(),
             static_cast<unsigned long long>(c->valid_end),
             static_cast<unsigned long long>(c->file_bytes));

  // What recovery does first with each record.
  for (const std::string& payload : c->records) {
    dynsolid::persist::JournalRecord record;
    if (!record.ParseFromString(payload)) break;
    (void)dynsolid::scene::ValidateValues(record.command(), "command");
  }
  return 0;
}
