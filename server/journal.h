// Durable files of a session: the append-only command journal and whole
// files replaced atomically (snapshots, the manifest). POSIX I/O, no gRPC.
//
// Journal framing: each record is
//     uint32 payload length (little-endian) | uint32 CRC-32C of the payload | payload
// appended with write(2) and made durable with fdatasync(2) before anything
// that depends on it (a command's acknowledgement) is released. A crash can
// leave a torn last record (short, or with a CRC that does not match):
// reading stops at the first record that is not whole and valid and the
// file is truncated there. That loses nothing acknowledged, because a
// record is acknowledged only after it is durable and records are appended
// in order.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace dynsolid::server {

// CRC-32C (Castagnoli, the iSCSI polynomial 0x1EDC6F41, reflected).
uint32_t Crc32c(absl::string_view bytes);

// `payload` framed as one journal record (8 header bytes + payload).
std::string FrameRecord(absl::string_view payload);

struct JournalContents {
  // Payloads of the whole, valid records from `from_offset` on, in order.
  std::vector<std::string> records;
  // Byte offset just past the last valid record: where appending resumes.
  uint64_t valid_end = 0;
  // File size when read; valid_end < file_bytes means a torn tail.
  uint64_t file_bytes = 0;
  // Why reading stopped before the end of the file (empty when it did not).
  std::string tail_problem;
};

// Reads the journal at `path` from byte `from_offset` (a record boundary,
// e.g. a snapshot's journal offset). A missing file reads as empty when
// from_offset is 0. DataLoss when the file is shorter than from_offset.
absl::StatusOr<JournalContents> ReadJournal(const std::string& path, uint64_t from_offset);

// Appends framed records. Not thread-safe: one writer (the session's
// persistence thread).
class JournalWriter {
 public:
  // Opens (creating it, mode 0600) `path` for appending and truncates it to
  // `size` bytes (dropping a torn tail found by ReadJournal).
  static absl::StatusOr<std::unique_ptr<JournalWriter>> Open(const std::string& path,
                                                             uint64_t size);
  ~JournalWriter();
  JournalWriter(const JournalWriter&) = delete;
  JournalWriter& operator=(const JournalWriter&) = delete;

  // Writes already framed bytes (one or more records) at the end.
  absl::Status Append(absl::string_view framed);
  // fdatasync: everything appended so far is durable when this returns OK.
  absl::Status Sync();
  uint64_t size() const { return size_; }

  // Makes sure the file's first `end` bytes have disk blocks (allocating
  // `extra` more beyond them when it must allocate; the file's size does
  // not change), so that appends up to `end` cannot fail for want of
  // space. ResourceExhausted ("no space left on the data disk ...") when
  // the disk is full. OK without doing anything on a file system that
  // cannot reserve. May be called from another thread than Append/Sync (the
  // session's simulation thread), but by one thread only.
  absl::Status Reserve(uint64_t end, uint64_t extra);
  uint64_t reserved() const { return reserved_.load(std::memory_order_acquire); }

 private:
  JournalWriter(int fd, std::string path, uint64_t size)
      : fd_(fd), path_(std::move(path)), size_(size), reserved_(size) {}
  int fd_;
  std::string path_;
  uint64_t size_;
  std::atomic<uint64_t> reserved_;
  std::atomic<bool> reserve_supported_{true};
};

// Replaces dir/name with `bytes` atomically: writes dir/name.tmp (mode
// `mode`), fsyncs it, renames it over dir/name and fsyncs dir. After a
// crash the file holds either the old or the new contents, never a mix.
absl::Status WriteFileAtomically(const std::string& dir, const std::string& name,
                                 absl::string_view bytes, int mode = 0600);

// The whole file. NotFound when it does not exist.
absl::StatusOr<std::string> ReadWholeFile(const std::string& path);

// mkdir -p (mode 0700 for new directories).
absl::Status MakeDirs(const std::string& path);

// Removes dir and everything in it (one level of files, as a session
// directory holds), then fsyncs its parent.
absl::Status RemoveDirTree(const std::string& dir);

}  // namespace dynsolid::server
