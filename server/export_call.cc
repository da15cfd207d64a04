#include "server/export_call.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <memory>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "server/grpc_status.h"
#include "server/sim_core.h"
#include "solver/export/design_export.h"
#include "solver/sculpt/design_scene.h"

namespace dynsolid::server {
namespace {

constexpr int kDefaultChunk = 1 << 20;
constexpr int kMinChunk = 4096, kMaxChunk = 4 << 20;

absl::StatusOr<exporter::Format> FormatOf(ExportRequest::Format f) {
  switch (f) {
    case ExportRequest::OBJ: return exporter::Format::kObj;
    case ExportRequest::STL: return exporter::Format::kStl;
    case ExportRequest::PLY: return exporter::Format::kPly;
    case ExportRequest::GLB: return exporter::Format::kGlb;
    case ExportRequest::VTU: return exporter::Format::kVtu;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "request.format: ", static_cast<int>(f), " is not a format (OBJ, STL, PLY, GLB, VTU, SCENE)"));
  }
}

// A file name from the scene's name: letters, digits, '-' and '_'.
std::string FileName(const std::string& scene, int64_t step, int level, const char* ext) {
  std::string base;
  for (char c : scene) base.push_back(std::isalnum(static_cast<unsigned char>(c)) || c == '-' ? c : '_');
  if (base.empty()) base = "design";
  return absl::StrCat(base.substr(0, 64), "-step", step, "-level", level, ".", ext);
}

class ExportCall final : public grpc::ServerWriteReactor<ExportChunk> {
 public:
  ExportCall(const ExportRequest& request, SessionRegistry& registry, WorkQueue& builds)
      : request_(request), builds_(builds) {
    absl::StatusOr<exporter::Format> format = exporter::Format::kObj;
    if (request.format() == ExportRequest::SCENE) {
      scene_file_ = true;
    } else {
      format = FormatOf(request.format());
    }
    if (!format.ok()) {
      Finish(ToGrpcStatus(format.status()));
      return;
    }
    format_ = *format;
    chunk_ = request.chunk_bytes() == 0 ? kDefaultChunk : request.chunk_bytes();
    if (chunk_ < kMinChunk || chunk_ > kMaxChunk) {
      Finish(ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat("request.chunk_bytes: ", request.chunk_bytes(), " is not 0 or in [",
                       kMinChunk, ", ", kMaxChunk, "]"))));
      return;
    }
    absl::StatusOr<std::shared_ptr<const SolidSession>> session =
        registry.Get(request.session().id(), request.session().token());
    if (!session.ok()) {
      Finish(ToGrpcStatus(session.status()));
      return;
    }
    // The shape at a step boundary, then the export off the loop.
    // An export subdivides to at most the cells a session's solid may have
    // (--max_cells): no export costs more memory than a session could.
    max_cells_ = registry.options().build.max_cells;
    (*session)->loop().Query([this](const SimCore* core) { Take(core); });
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the client went away"));
      return;
    }
    WriteNext();
  }
  void OnDone() override { delete this; }

 private:
  // On the simulation thread: copy what the export needs.
  void Take(const SimCore* core) {
    if (core == nullptr) {
      Finish(ToGrpcStatus(absl::UnavailableError("the session is closed")));
      return;
    }
    const solid::Solid& s = core->solid();
    auto d = std::make_shared<scene::Discretization>();
    d->hierarchy.control = s.discretization().hierarchy.control;
    d->control_sharp = s.discretization().control_sharp;
    positions_ = s.control_positions();
    rest_ = s.discretization().control().positions();
    if (format_ == exporter::Format::kVtu && !scene_file_) {
      // The samples as painted, for the volume's cell data (their means
      // are taken off the loop, on the solid kept alive here).
      solid_ = core->shared_solid();
      design_samples_ = s.SaveDesign();
    }
    discretization_ = std::move(d);
    step_ = core->steps();
    name_ = core->scene().name();
    level_ = request_.has_level() ? request_.level() : s.discretization().hierarchy.levels;
    if (scene_file_) {
      if (level_ != s.discretization().hierarchy.levels) {
        Finish(ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat(
            "request.level: a scene file is saved at the session's level ",
            s.discretization().hierarchy.levels, " (its painted samples belong to that level's "
            "elements), not ", level_))));
        return;
      }
      // The design's samples and clay are read here, at the step boundary
      // (a walk over the elements' sample arrays); the text is made off
      // the loop.
      design_ = std::make_shared<Scene>(sculpt::DesignScene(core->scene(), s));
      cells_ = static_cast<int64_t>(s.discretization().hierarchy.control_cell.size());
    }
    builds_.Post([this](bool run) { Make(run); });
  }

  // On the builds queue.
  void Make(bool run) {
    if (!run) {
      Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
      return;
    }
    if (scene_file_) {
      MakeSceneFile();
      WriteNext();
      return;
    }
    if (solid_ != nullptr) {
      absl::StatusOr<exporter::MaterialFields> fields =
          exporter::MaterialFieldsOf(solid_->discretization(), design_samples_);
      if (fields.ok()) materials_ = std::make_shared<exporter::MaterialFields>(*std::move(fields));
    }
    exporter::ExportOptions options;
    options.format = format_;
    options.level = level_;
    options.color_field = request_.color_field();
    if (max_cells_ > 0) options.max_cells = max_cells_;
    absl::StatusOr<exporter::Exported> made = exporter::ExportDesign(
        exporter::DesignInput{discretization_.get(), positions_, rest_, materials_.get()}, options);
    if (!made.ok()) {
      Finish(ToGrpcStatus(absl::Status(made.status().code(),
                                       absl::StrCat("request.", made.status().message()))));
      return;
    }
    made_ = *std::move(made);
    file_name_ = FileName(name_, step_, level_, exporter::Extension(format_));
    WriteNext();
  }

  // The design as a scene file: a comment saying where it came from, then
  // the scene's text.
  void MakeSceneFile() {
    made_.bytes = sculpt::SceneText(
        *design_, absl::StrCat("dynsolid scene: a design saved by Export SCENE (docs/export.md) from "
                               "session ", request_.session().id(), " at step ", step_, ".\n"
                               "dynsolid-client create --scene_file FILE takes it back."));
    made_.cells = cells_;
    file_name_ = FileName(name_, step_, level_, "textproto");
  }

  void WriteNext() {
    const int64_t total = static_cast<int64_t>(made_.bytes.size());
    if (offset_ >= total && offset_ > 0) {
      Finish(grpc::Status::OK);
      return;
    }
    chunk_out_.Clear();
    const int64_t n = std::min<int64_t>(chunk_, total - offset_);
    chunk_out_.set_data(made_.bytes.substr(offset_, n));
    chunk_out_.set_offset(offset_);
    chunk_out_.set_total_bytes(total);
    if (offset_ == 0) {
      chunk_out_.set_file_name(file_name_);
      chunk_out_.set_media_type(scene_file_ ? "text/plain" : exporter::MediaType(format_));
      chunk_out_.set_step(step_);
      chunk_out_.set_level(level_);
      chunk_out_.set_cells(made_.cells);
      chunk_out_.set_surface_faces(made_.surface_faces);
    }
    offset_ += std::max<int64_t>(n, 1);  // an empty file is one empty chunk
    StartWrite(&chunk_out_);
  }

  const ExportRequest request_;
  WorkQueue& builds_;
  exporter::Format format_ = exporter::Format::kGlb;
  bool scene_file_ = false;  // SCENE: design_ as text
  std::shared_ptr<const Scene> design_;
  // VTU: the solid (its discretization) and its samples, taken on the
  // loop; their means, made off it.
  std::shared_ptr<const solid::Solid> solid_;
  Design design_samples_;
  std::shared_ptr<const exporter::MaterialFields> materials_;
  int64_t cells_ = 0;
  int64_t max_cells_ = 0;
  int chunk_ = kDefaultChunk;
  std::shared_ptr<const scene::Discretization> discretization_;
  Points positions_, rest_;
  int64_t step_ = 0;
  int level_ = 0;
  std::string name_, file_name_;
  exporter::Exported made_;
  int64_t offset_ = 0;
  ExportChunk chunk_out_;
};

class Refused final : public grpc::ServerWriteReactor<ExportChunk> {
 public:
  explicit Refused(const absl::Status& status) { Finish(ToGrpcStatus(status)); }
  void OnDone() override { delete this; }
};

}  // namespace

grpc::ServerWriteReactor<ExportChunk>* RefuseExport(const absl::Status& status) {
  return new Refused(status);
}

grpc::ServerWriteReactor<ExportChunk>* StartExport(grpc::CallbackServerContext* context,
                                                   const ExportRequest* request,
                                                   SessionRegistry& registry, WorkQueue& builds) {
  (void)context;
  return new ExportCall(*request, registry, builds);
}

}  // namespace dynsolid::server
