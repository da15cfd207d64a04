#include "clients/lib/watcher.h"

#include <cstdio>

#include <algorithm>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace dynsolid::client {
namespace {

using Clock = std::chrono::steady_clock;

// Stream statuses after which reconnecting cannot help: the shared ones
// and RESOURCE_EXHAUSTED (a server limit).
bool Fatal(grpc::StatusCode code) {
  return IsFinalStreamStatus(code) || code == grpc::StatusCode::RESOURCE_EXHAUSTED;
}

}  // namespace

Watcher::Watcher(ChannelFactory channels, SessionRef session, WatcherOptions options)
    : channels_(std::move(channels)),
      session_(std::move(session)),
      options_(std::move(options)) {
  thread_ = std::thread([this] { Loop(); });
}

Watcher::~Watcher() { (void)Stop(); }

void Watcher::Loop() {
  WatchRequest request;
  *request.mutable_session() = session_;
  request.set_rate_hz(options_.rate_hz);
  request.set_displacement(options_.displacement);
  request.set_strain(options_.strain);
  request.set_stiffness(options_.stiffness);
  request.set_mass(options_.mass);
  request.set_client_id(options_.client_id);
  Clock::time_point broken_since{};
  bool broken = false;
  int backoff_ms = 50;
  int redirects = 0;  // in a row, without a frame in between
  std::unique_ptr<Sessions::Stub> stub = Sessions::NewStub(channels_());
  for (;;) {
    if (broken) stub = Sessions::NewStub(channels_());  // a fresh connection
    grpc::ClientContext context;
    {
      absl::MutexLock lock(&mu_);
      if (stop_) break;
      context_ = &context;
      decoder_.Reset();  // a new stream starts with a keyframe
    }
    const Clock::time_point opened = Clock::now();
    std::unique_ptr<grpc::ClientReader<Frame>> reader = stub->Watch(&context, request);
    Frame frame;
    bool got_frame = false;
    bool bad_frame = false;
    while (reader->Read(&frame)) {
      got_frame = true;
      const Clock::time_point now = Clock::now();
      Surface to_record;
      bool record = false;
      {
        absl::MutexLock lock(&mu_);
        const absl::Status applied = decoder_.Apply(frame);
        if (!applied.ok()) {
          error_ = absl::DataLossError(absl::StrCat("watch frame at step ", frame.step(), ": ",
                                                    applied.message()));
          bad_frame = true;
          context.TryCancel();
          break;
        }
        WatcherCounts& c = counts_;
        if (c.frames == 0) {
          first_time_ = now;
          c.first_step = frame.step();
          first_ = decoder_.surface();
        }
        ++c.frames;
        if (frame.has_keyframe()) {
          ++c.keyframes;
        } else {
          ++c.deltas;
        }
        c.skipped += frame.skipped();
        c.bytes += static_cast<int64_t>(frame.ByteSizeLong());
        const SurfaceFields& f =
            frame.has_keyframe() ? frame.keyframe().fields() : frame.delta().fields();
        c.field_bytes += int64_t{4} * (f.displacement_size() + f.strain_size() +
                                       f.stiffness_size() + f.mass_size());
        c.raw_float32_bytes += int64_t{12} * decoder_.surface().vertex_count();
        c.last_step = frame.step();
        c.seconds = std::chrono::duration<double>(now - first_time_).count();
        if (options_.record_every > 0 && (c.frames - 1) % options_.record_every == 0) {
          record = true;
          to_record = decoder_.surface();
        }
      }
      if (record) Record(to_record);
      if (options_.on_frame) options_.on_frame(frame.step(), now);
    }
    const grpc::Status status = reader->Finish();
    absl::MutexLock lock(&mu_);
    context_ = nullptr;
    if (stop_ || bad_frame) break;
    if (got_frame) redirects = 0;
    if (redirects < kMaxRedirects && channels_.Follow(status)) {
      ++redirects;  // the session lives on another replica: watch it there
      broken = true;
      broken_since = Clock::now();
      continue;
    }
    if (Fatal(status.error_code())) {
      error_ = ToAbslStatus(status, "Watch");
      break;
    }
    const Clock::time_point now = Clock::now();
    if (got_frame || now - opened > std::chrono::seconds(1)) {
      broken = false;
      backoff_ms = 50;
    }
    if (!broken) {
      broken = true;
      broken_since = now;
    }
    if (now - broken_since > absl::ToChronoNanoseconds(options_.reconnect_timeout)) {
      error_ = absl::UnavailableError(
          absl::StrCat("Watch: no working stream for ",
                       absl::FormatDuration(options_.reconnect_timeout), " (last: ",
                       status.error_message(), ")"));
      break;
    }
    ++counts_.reconnects;
    if (options_.log) {
      options_.log(absl::StrCat("watch: stream ended (", status.error_code(), " ",
                                status.error_message(), "); reconnect ", counts_.reconnects));
    }
    mu_.AwaitWithTimeout(absl::Condition(&stop_), absl::Milliseconds(backoff_ms));
    backoff_ms = std::min(backoff_ms * 2, 1000);
  }
  absl::MutexLock lock(&mu_);
  ended_ = true;
}

void Watcher::Record(const Surface& s) {
  const std::string stem = absl::StrFormat("%s/frame_%08d", options_.frames_dir, s.step);
  std::vector<std::string> written;
  absl::Status status;
  if (options_.write_obj) {
    status.Update(WriteObj(s, stem + ".obj"));
    written.push_back(stem + ".obj");
  }
  if (options_.write_vtu) {
    status.Update(WriteVtu(s, stem + ".vtu"));
    written.push_back(stem + ".vtu");
  }
  absl::MutexLock lock(&mu_);
  if (status.ok() && options_.write_vtu) {
    // The index of the frames so far: ParaView opens it as one animation
    // (frames as the stream delivered them: some steps skipped when the
    // network was slow, positions quantized; dynsolid-replay gives every
    // frame exactly, docs/export.md).
    absl::StrAppendFormat(&pvd_entries_, "    <DataSet timestep=\"%.17g\" part=\"0\" file=\"%s\"/>\n",
                          s.time, absl::StrFormat("frame_%08d.vtu", s.step));
    const std::string pvd = absl::StrCat(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n",
        pvd_entries_, "  </Collection>\n</VTKFile>\n");
    const std::string path = options_.frames_dir + "/frames.pvd";
    std::FILE* f = std::fopen((path + ".tmp").c_str(), "wb");
    bool ok = f != nullptr && std::fwrite(pvd.data(), 1, pvd.size(), f) == pvd.size();
    if (f != nullptr) ok = std::fclose(f) == 0 && ok;
    if (!ok || std::rename((path + ".tmp").c_str(), path.c_str()) != 0) {
      status = absl::UnavailableError(absl::StrCat("cannot write ", path));
    }
  }
  if (!status.ok()) {
    if (error_.ok()) error_ = status;
    return;
  }
  ++counts_.frames_written;
  for (std::string& f : written) counts_.files.push_back(std::move(f));
}

absl::StatusOr<Surface> Watcher::WaitForStep(int64_t step, absl::Duration timeout) {
  absl::MutexLock lock(&mu_);
  auto ready = [this, step]() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    return ended_ || (decoder_.has_keyframe() && decoder_.step() >= step);
  };
  mu_.AwaitWithTimeout(absl::Condition(&ready), timeout);
  if (decoder_.has_keyframe() && decoder_.step() >= step) return decoder_.surface();
  if (!error_.ok()) return error_;
  return absl::DeadlineExceededError(absl::StrCat(
      "the watcher got no frame at step >= ", step, " within ", absl::FormatDuration(timeout),
      " (its last frame: step ", decoder_.has_keyframe() ? decoder_.step() : -1, ")"));
}

Surface Watcher::Current() const {
  absl::MutexLock lock(&mu_);
  return decoder_.surface();
}

Surface Watcher::First() const {
  absl::MutexLock lock(&mu_);
  return first_;
}

WatcherCounts Watcher::Counts() const {
  absl::MutexLock lock(&mu_);
  return counts_;
}

absl::Status Watcher::Stop() {
  {
    absl::MutexLock lock(&mu_);
    stop_ = true;
    if (context_ != nullptr) context_->TryCancel();
  }
  if (thread_.joinable()) thread_.join();
  absl::MutexLock lock(&mu_);
  return error_;
}

}  // namespace dynsolid::client
