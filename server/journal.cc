#include "server/journal.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <memory>

#include "absl/strings/str_cat.h"

namespace dynsolid::server {
namespace {

std::array<uint32_t, 256> MakeCrcTable() {
  std::array<uint32_t, 256> t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
    t[i] = c;
  }
  return t;
}

absl::Status Errno(absl::string_view what, const std::string& path) {
  const int e = errno;
  if (e == ENOSPC || e == EDQUOT) {
    return absl::ResourceExhaustedError(absl::StrCat("no space left on the data disk: ", what, " ",
                                                     path, ": ", std::strerror(e)));
  }
  return absl::Status(e == ENOENT ? absl::StatusCode::kNotFound : absl::StatusCode::kInternal,
                      absl::StrCat(what, " ", path, ": ", std::strerror(e)));
}

void PutU32(uint32_t v, char* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<char>((v >> (8 * i)) & 0xff);
}
uint32_t GetU32(const char* in) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v |= static_cast<uint32_t>(static_cast<unsigned char>(in[i])) << (8 * i);
  return v;
}

absl::Status WriteAll(int fd, absl::string_view bytes, const std::string& path) {
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      return Errno("cannot write", path);
    }
    done += static_cast<size_t>(n);
  }
  return absl::OkStatus();
}

absl::Status SyncDir(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return Errno("cannot open directory", dir);
  const int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0) return Errno("cannot fsync directory", dir);
  return absl::OkStatus();
}

}  // namespace

uint32_t Crc32c(absl::string_view bytes) {
  static const std::array<uint32_t, 256> table = MakeCrcTable();
  uint32_t c = 0xffffffffu;
  for (const char ch : bytes) c = table[(c ^ static_cast<unsigned char>(ch)) & 0xff] ^ (c >> 8);
  return c ^ 0xffffffffu;
}

std::string FrameRecord(absl::string_view payload) {
  std::string out(8 + payload.size(), '\0');
  PutU32(static_cast<uint32_t>(payload.size()), out.data());
  PutU32(Crc32c(payload), out.data() + 4);
  std::memcpy(out.data() + 8, payload.data(), payload.size());
  return out;
}

absl::StatusOr<JournalContents> ReadJournal(const std::string& path, uint64_t from_offset) {
  JournalContents c;
  absl::StatusOr<std::string> file = ReadWholeFile(path);
  if (!file.ok()) {
    if (absl::IsNotFound(file.status()) && from_offset == 0) return c;
    return file.status();
  }
  c.file_bytes = file->size();
  if (from_offset > file->size()) {
    return absl::DataLossError(absl::StrCat("journal ", path, " has ", file->size(),
                                            " bytes, fewer than the snapshot's offset ",
                                            from_offset));
  }
  uint64_t at = from_offset;
  while (at < file->size()) {
    if (file->size() - at < 8) {
      c.tail_problem = absl::StrCat("a torn record header at byte ", at);
      break;
    }
    const uint32_t len = GetU32(file->data() + at);
    const uint32_t crc = GetU32(file->data() + at + 4);
    if (file->size() - at - 8 < len) {
      c.tail_problem = absl::StrCat("a torn record at byte ", at, " (", len,
                                    " payload bytes announced, ", file->size() - at - 8,
                                    " present)");
      break;
    }
    absl::string_view payload(file->data() + at + 8, len);
    if (Crc32c(payload) != crc) {
      c.tail_problem = absl::StrCat("a record with a bad CRC at byte ", at);
      break;
    }
    c.records.emplace_back(payload);
    at += 8 + len;
  }
  c.valid_end = at;
  return c;
}

absl::StatusOr<std::unique_ptr<JournalWriter>> JournalWriter::Open(const std::string& path,
                                                                   uint64_t size) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
  if (fd < 0) return Errno("cannot open journal", path);
  if (::ftruncate(fd, static_cast<off_t>(size)) != 0 ||
      ::lseek(fd, static_cast<off_t>(size), SEEK_SET) < 0 || ::fdatasync(fd) != 0) {
    absl::Status s = Errno("cannot prepare journal", path);
    ::close(fd);
    return s;
  }
  return std::unique_ptr<JournalWriter>(new JournalWriter(fd, path, size));
}

absl::Status JournalWriter::Reserve(uint64_t end, uint64_t extra) {
  const uint64_t reserved = reserved_.load(std::memory_order_acquire);
  if (end <= reserved || !reserve_supported_.load(std::memory_order_relaxed)) {
    return absl::OkStatus();
  }
  // Blocks past the end of the file, its size unchanged: appends into them
  // need no new blocks, so they cannot fail with ENOSPC (tmpfs, ext4, xfs,
  // btrfs allocate them here).
  const uint64_t target = end + extra;
  int rc;
  do {
    rc = ::fallocate(fd_, FALLOC_FL_KEEP_SIZE, static_cast<off_t>(reserved),
                     static_cast<off_t>(target - reserved));
  } while (rc != 0 && errno == EINTR);
  if (rc != 0) {
    if (errno == EOPNOTSUPP || errno == ENOSYS) {
      // A file system that cannot reserve: appends may still fail, and are
      // then handled as write errors (SessionLoop::Persist).
      reserve_supported_.store(false, std::memory_order_relaxed);
      return absl::OkStatus();
    }
    return Errno(absl::StrCat("cannot reserve ", target - reserved, " bytes in journal"), path_);
  }
  reserved_.store(target, std::memory_order_release);
  return absl::OkStatus();
}

JournalWriter::~JournalWriter() {
  if (fd_ >= 0) {
    ::fdatasync(fd_);
    ::close(fd_);
  }
}

absl::Status JournalWriter::Append(absl::string_view framed) {
  if (absl::Status s = WriteAll(fd_, framed, path_); !s.ok()) return s;
  size_ += framed.size();
  return absl::OkStatus();
}

absl::Status JournalWriter::Sync() {
  if (::fdatasync(fd_) != 0) return Errno("cannot fdatasync journal", path_);
  return absl::OkStatus();
}

absl::Status WriteFileAtomically(const std::string& dir, const std::string& name,
                                 absl::string_view bytes, int mode) {
  const std::string tmp = absl::StrCat(dir, "/", name, ".tmp");
  const std::string final_path = absl::StrCat(dir, "/", name);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, mode);
  if (fd < 0) return Errno("cannot create", tmp);
  absl::Status s = WriteAll(fd, bytes, tmp);
  if (s.ok() && ::fsync(fd) != 0) s = Errno("cannot fsync", tmp);
  ::close(fd);
  if (!s.ok()) {
    ::unlink(tmp.c_str());  // a partial copy would only hold space
    return s;
  }
  if (::rename(tmp.c_str(), final_path.c_str()) != 0) return Errno("cannot rename", tmp);
  return SyncDir(dir);
}

absl::StatusOr<std::string> ReadWholeFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Errno("cannot open", path);
  std::string out;
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof(buf));
    if (n < 0) {
      if (errno == EINTR) continue;
      absl::Status s = Errno("cannot read", path);
      ::close(fd);
      return s;
    }
    if (n == 0) break;
    out.append(buf, static_cast<size_t>(n));
  }
  ::close(fd);
  return out;
}

absl::Status MakeDirs(const std::string& path) {
  if (path.empty()) return absl::InvalidArgumentError("empty directory path");
  for (size_t at = 1; at <= path.size(); ++at) {
    if (at < path.size() && path[at] != '/') continue;
    const std::string prefix = path.substr(0, at);
    if (::mkdir(prefix.c_str(), 0700) != 0 && errno != EEXIST) {
      return Errno("cannot create directory", prefix);
    }
  }
  return absl::OkStatus();
}

absl::Status RemoveDirTree(const std::string& dir) {
  DIR* d = ::opendir(dir.c_str());
  if (d == nullptr) return Errno("cannot open directory", dir);
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name == "." || name == "..") continue;
    ::unlink(absl::StrCat(dir, "/", name).c_str());
  }
  ::closedir(d);
  if (::rmdir(dir.c_str()) != 0) return Errno("cannot remove directory", dir);
  const size_t slash = dir.rfind('/');
  return SyncDir(slash == std::string::npos ? std::string(".") : dir.substr(0, slash));
}

}  // namespace dynsolid::server
