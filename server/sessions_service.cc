#include "server/sessions_service.h"

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <optional>

#include "absl/strings/str_cat.h"
#include "solver/export/design_export.h"
#include "solver/export/section.h"
#include "solver/subdivision/cell_count.h"
#include "server/export_call.h"
#include "server/grpc_status.h"
#include "dynsolid/journal.pb.h"
#include "server/journal.h"
#include "server/log.h"
#include "server/parsed_request.h"
#include "server/probe.h"
#include "server/probe_rpc.h"
#include "server/vec3.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::server {
namespace {

// The index gRPC's generated code gives the method `name` of
// dynsolid.Sessions (the order of the service's descriptor).
int MethodIndex(const char* name) {
  const google::protobuf::ServiceDescriptor* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(
          Sessions::service_full_name());
  const google::protobuf::MethodDescriptor* method =
      service != nullptr ? service->FindMethodByName(name) : nullptr;
  if (method == nullptr) {
    ServerLog().critical("dynsolid.Sessions has no method {}", name);
    std::abort();
  }
  return method->index();
}

}  // namespace

template <class Request, class Reply>
void SessionsService::ParseFirst(const char* name,
                                 grpc::ServerUnaryReactor* (SessionsService::*handler)(
                                     grpc::CallbackServerContext*, const Request*, Reply*)) {
  MarkMethodCallback(
      MethodIndex(name),
      new grpc::internal::CallbackUnaryHandler<Parsed<Request>, Reply>(
          [this, handler](grpc::CallbackServerContext* context, const Parsed<Request>* request,
                          Reply* reply) {
            if (!request->parsed) {
              grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
              reactor->Finish(ToGrpcStatus(NotAMessage(*request)));
              return reactor;
            }
            return (this->*handler)(context, &request->message, reply);
          }));
}

SessionsService::SessionsService(SessionRegistry& registry, Replicas& replicas, int max_sessions,
                                 WorkQueue& builds, WorkQueue& encoders,
                                 StreamOptions stream_options)
    : registry_(registry), replicas_(replicas), max_sessions_(max_sessions), builds_(builds),
      encoders_(encoders), stream_options_(stream_options) {
  // gRPC's generated handlers would answer a request that does not parse
  // with UNIMPLEMENTED and no message (unary) or end the reads as a
  // half-close (streams, which then finish OK): every method but Watch
  // (raw, parsed in streams.cc) is registered again with Parsed<Request>.
  ParseFirst("CreateSession", &SessionsService::CreateSession);
  ParseFirst("GetSession", &SessionsService::GetSession);
  ParseFirst("ListSessions", &SessionsService::ListSessions);
  ParseFirst("CloseSession", &SessionsService::CloseSession);
  ParseFirst("GetStats", &SessionsService::GetStats);
  ParseFirst("Inspect", &SessionsService::Inspect);
  ParseFirst("Pick", &SessionsService::Pick);
  ParseFirst("Section", &SessionsService::Section);
  ParseFirst("ListScenes", &SessionsService::ListScenes);
  ParseFirst("GetCommandLog", &SessionsService::GetCommandLog);
  ParseFirst("GetServerInfo", &SessionsService::GetServerInfo);
  MarkMethodCallback(MethodIndex("Commands"),
                     new grpc::internal::CallbackBidiHandler<Parsed<CommandRequest>, CommandReply>(
                         [this](grpc::CallbackServerContext* context) {
                           return StartCommands(context, registry_);
                         }));
  MarkMethodCallback(MethodIndex("Probe"),
                     new grpc::internal::CallbackBidiHandler<Parsed<ProbeRequest>, ProbeReply>(
                         [this](grpc::CallbackServerContext* context) {
                           return StartProbe(context, registry_);
                         }));
  // Export: the shape at a step boundary, the file made on the builds
  // queue and streamed (export_call.h).
  MarkMethodCallback(
      MethodIndex("Export"),
      new grpc::internal::CallbackServerStreamingHandler<Parsed<ExportRequest>, ExportChunk>(
          [this](grpc::CallbackServerContext* context, const Parsed<ExportRequest>* request) {
            if (!request->parsed) return RefuseExport(NotAMessage(*request));
            return StartExport(context, &request->message, registry_, builds_);
          }));
}

void SessionsService::OnBuilds(grpc::ServerUnaryReactor* reactor, std::function<void()> work) {
  builds_.Post([reactor, work = std::move(work)](bool run) {
    if (!run) {
      reactor->Finish(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
      return;
    }
    work();
  });
}

grpc::ServerUnaryReactor* SessionsService::CreateSession(grpc::CallbackServerContext* context,
                                                         const CreateSessionRequest* request,
                                                         Session* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const bool placed = context->client_metadata().count(kPlacedHereKey) > 0;
  // context, request and response stay valid until Finish.
  OnBuilds(reactor, [this, context, request, response, reactor, placed] {
    Replicas::Peer* peer = (placed || !replicas_.has_peers()) ? nullptr : ChoosePlace();
    if (peer != nullptr) {
      CreateOn(peer, context, request, response, reactor);
    } else {
      CreateHere(context, request, response, reactor);
    }
  });
  return reactor;
}

void SessionsService::CreateHere(grpc::CallbackServerContext* context,
                                 const CreateSessionRequest* request, Session* response,
                                 grpc::ServerUnaryReactor* reactor) {
  absl::StatusOr<std::shared_ptr<const SolidSession>> session =
      registry_.Create(*request, [context] { return context->IsCancelled(); });
  if (!session.ok()) {
    ServerLog().info("CreateSession from {} failed: {}", context->peer(),
                     session.status().ToString());
    reactor->Finish(ToGrpcStatus(session.status()));
    return;
  }
  const SolidSession& s = **session;
  *response = ToProto(s);
  ServerLog().info(
      "session {} created for {}: scene {}, {} cells at level {} ({} cubic, {} linear, {} "
      "pyramid elements) in {:.1f} ms",
      s.id(), context->peer(), s.scene_name(), s.stats().cells(), s.stats().levels(),
      s.stats().cubic_elements(), s.stats().linear_elements(), s.stats().pyramid_elements(),
      s.stats().build_milliseconds());
  reactor->Finish(grpc::Status::OK);
}

namespace {

// Load as a fraction of capacity; what placement compares.
double LoadOf(int sessions, int creating, int forwarding, int max_sessions) {
  return static_cast<double>(sessions + creating + forwarding) / std::max(1, max_sessions);
}

}  // namespace

Replicas::Peer* SessionsService::ChoosePlace() {
  double best = LoadOf(registry_.size(), registry_.creating(), 0, max_sessions_);
  Replicas::Peer* choice = nullptr;  // this replica wins ties
  for (const auto& peer : replicas_.peers()) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(500));
    ServerInfo info;
    const grpc::Status s = peer->stub->GetServerInfo(&ctx, google::protobuf::Empty(), &info);
    if (!s.ok()) {
      ServerLog().info("placement: peer {} at {} does not answer ({}); passed over",
                       peer->replica, peer->address, s.error_message());
      continue;
    }
    const int forwarding = peer->forwarding.load();
    if (!info.accepting() ||
        info.sessions() + info.creating() + forwarding >= info.max_sessions()) {
      continue;
    }
    const double load =
        LoadOf(info.sessions(), info.creating(), forwarding, info.max_sessions());
    if (load < best) {
      best = load;
      choice = peer.get();
    }
  }
  return choice;
}

void SessionsService::CreateOn(Replicas::Peer* peer, grpc::CallbackServerContext* context,
                               const CreateSessionRequest* request, Session* response,
                               grpc::ServerUnaryReactor* reactor) {
  // Deadline and cancellation follow the caller's call.
  std::shared_ptr<grpc::ClientContext> ctx = grpc::ClientContext::FromCallbackServerContext(*context);
  ctx->AddMetadata(kPlacedHereKey, replicas_.name());
  ++peer->forwarding;
  ServerLog().info("CreateSession from {}: placed on peer {} at {}", context->peer(),
                   peer->replica, peer->address);
  peer->stub->async()->CreateSession(
      ctx.get(), request, response,
      [this, peer, ctx, context, request, response, reactor](grpc::Status s) {
        --peer->forwarding;
        const bool peer_cannot = s.error_code() == grpc::StatusCode::UNAVAILABLE ||
                                 s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED;
        if (!peer_cannot || context->IsCancelled()) {
          reactor->Finish(s);
          return;
        }
        ServerLog().info("peer {} could not take the session ({}); building it here",
                         peer->replica, s.error_message());
        response->Clear();
        OnBuilds(reactor, [this, context, request, response, reactor] {
          CreateHere(context, request, response, reactor);
        });
      });
}

ServerInfo SessionsService::Info() const {
  ServerInfo info;
  info.set_replica(replicas_.name());
  info.set_address(replicas_.address());
  info.set_sessions(registry_.size());
  info.set_creating(registry_.creating());
  info.set_max_sessions(max_sessions_);
  info.set_accepting(registry_.accepting());
  for (const auto& peer : replicas_.peers()) {
    ServerInfo::Peer* p = info.add_peers();
    p->set_replica(peer->replica);
    p->set_address(peer->address);
  }
  return info;
}

Session SessionsService::ToProto(const SolidSession& s) const {
  Session out = s.ToProto();
  out.set_replica(replicas_.name());
  out.set_address(replicas_.address());
  return out;
}

grpc::ServerUnaryReactor* SessionsService::GetServerInfo(grpc::CallbackServerContext* context,
                                                         const google::protobuf::Empty* request,
                                                         ServerInfo* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  *response = Info();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::GetSession(grpc::CallbackServerContext* context,
                                                      const SessionRef* request,
                                                      Session* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::StatusOr<std::shared_ptr<const SolidSession>> session =
      registry_.Get(request->id(), request->token());
  if (session.ok()) *response = ToProto(**session);
  reactor->Finish(ToGrpcStatus(session.status()));
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::ListSessions(grpc::CallbackServerContext* context,
                                                        const ListSessionsRequest* request,
                                                        ListSessionsResponse* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  for (const auto& session : registry_.List()) {
    *response->add_sessions() = session->ToListEntry();
  }
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::CloseSession(grpc::CallbackServerContext* context,
                                                        const SessionRef* request,
                                                        google::protobuf::Empty* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  const absl::Status closed = registry_.Close(request->id(), request->token());
  if (closed.ok()) ServerLog().info("session {} closed by {}", request->id(), context->peer());
  reactor->Finish(ToGrpcStatus(closed));
  return reactor;
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* SessionsService::Watch(
    grpc::CallbackServerContext* context, const grpc::ByteBuffer* request) {
  return StartWatch(context, request, registry_, encoders_, stream_options_);
}

grpc::ServerUnaryReactor* SessionsService::GetStats(grpc::CallbackServerContext* context,
                                                    const SessionRef* request,
                                                    SessionStats* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  absl::StatusOr<std::shared_ptr<const SolidSession>> session =
      registry_.Get(request->id(), request->token());
  if (session.ok()) *response = (*session)->loop().Stats();
  reactor->Finish(ToGrpcStatus(session.status()));
  return reactor;
}

std::shared_ptr<const SolidSession> SessionsService::SessionOrFinish(
    const SessionRef& ref, grpc::ServerUnaryReactor* reactor) {
  absl::StatusOr<std::shared_ptr<const SolidSession>> session = registry_.Get(ref.id(), ref.token());
  if (!session.ok()) {
    reactor->Finish(ToGrpcStatus(session.status()));
    return nullptr;
  }
  return *std::move(session);
}

grpc::ServerUnaryReactor* SessionsService::Inspect(grpc::CallbackServerContext* context,
                                                   const InspectRequest* request,
                                                   InspectReply* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  std::shared_ptr<const SolidSession> session = SessionOrFinish(request->session(), reactor);
  if (session == nullptr) return reactor;
  // Answered by the simulation thread at a step boundary; response and
  // reactor stay valid until Finish.
  session->loop().Inspect(
      *request,
      [reactor, response](absl::StatusOr<InspectReply> r) {
        if (r.ok()) *response = *std::move(r);
        reactor->Finish(ToGrpcStatus(r.status()));
      },
      [context] { return context->IsCancelled(); });
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::Pick(grpc::CallbackServerContext* context,
                                                const PickRequest* request, PickReply* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  std::shared_ptr<const SolidSession> session = SessionOrFinish(request->session(), reactor);
  if (session == nullptr) return reactor;
  if (absl::Status s = scene::ValidateValues(*request, "request"); !s.ok()) {
    reactor->Finish(ToGrpcStatus(s));
    return reactor;
  }
  const Eigen::Vector3d origin(request->origin().x(), request->origin().y(),
                               request->origin().z());
  const Eigen::Vector3d direction(request->direction().x(), request->direction().y(),
                                  request->direction().z());
  // Answered by the simulation thread between two steps.
  session->loop().Query([reactor, response, origin, direction](const SimCore* core) {
    if (core == nullptr) {
      reactor->Finish(ToGrpcStatus(absl::UnavailableError("the session is closed")));
      return;
    }
    absl::StatusOr<std::optional<solid::Solid::PickHit>> hit =
        core->solid().Pick(origin, direction);
    if (!hit.ok()) {
      reactor->Finish(ToGrpcStatus(absl::Status(
          hit.status().code(), absl::StrCat("request.", hit.status().message()))));
      return;
    }
    response->set_step(core->steps());
    if (hit->has_value()) {
      const solid::Solid::PickHit& h = **hit;
      response->set_hit(true);
      *response->mutable_point() = ToVec3(h.point);
      *response->mutable_material_point() = ToVec3(h.material_point);
      *response->mutable_normal() = ToVec3(h.normal);
      response->set_surface_quad(h.quad);
      response->set_control_cell(h.control_cell);
      response->set_control_face(h.control_face);
      response->set_distance(h.distance);
    }
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

namespace {

// The built-in scenes as a picker shows them (a scene that does not load
// is listed with its error as its description: the server still serves).
SceneList MakeSceneList() {
  SceneList out;
  for (const std::string& name : scene::BuiltinSceneNames()) {
    SceneList::Entry* e = out.add_scenes();
    e->set_name(name);
    absl::StatusOr<Scene> scene = scene::BuiltinScene(name);
    if (!scene.ok()) {
      e->set_description(std::string(scene.status().message()));
      continue;
    }
    e->set_description(scene->description());
    e->set_levels(scene->subdivision().levels());
    absl::StatusOr<mesh::MeshInput> mesh = scene::ControlMeshInput(*scene, scene::BuiltinSceneDir());
    if (!mesh.ok() || mesh->vertices.rows() == 0) continue;
    const std::vector<int32_t> refine(scene->mesh().refine_cells().begin(),
                                      scene->mesh().refine_cells().end());
    e->set_control_cells(static_cast<int32_t>(mesh->cells.size()) +
                         static_cast<int32_t>(7 * refine.size()));
    e->set_cells(subdivision::EstimateFineCells(*mesh, refine, scene->subdivision().levels()));
    const Eigen::RowVector3d size = mesh->vertices.colwise().maxCoeff() - mesh->vertices.colwise().minCoeff();
    *e->mutable_size() = ToVec3(size.transpose());
  }
  return out;
}

}  // namespace

grpc::ServerUnaryReactor* SessionsService::ListScenes(grpc::CallbackServerContext* context,
                                                      const google::protobuf::Empty* request,
                                                      SceneList* response) {
  (void)request;
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  OnBuilds(reactor, [reactor, response] {
    static const SceneList* list = new SceneList(MakeSceneList());
    *response = *list;
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::Section(grpc::CallbackServerContext* context,
                                                   const SectionRequest* request,
                                                   SectionReply* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  std::shared_ptr<const SolidSession> session = SessionOrFinish(request->session(), reactor);
  if (session == nullptr) return reactor;
  if (absl::Status s = scene::ValidateValues(*request, "request"); !s.ok()) {
    reactor->Finish(ToGrpcStatus(s));
    return reactor;
  }
  struct Job {
    Eigen::Vector3d point, normal;
    std::string field;
    std::shared_ptr<solid::Solid> solid;  // keeps its discretization alive
    Points positions, rest;
    std::optional<Design> design;  // stiffness: the samples as painted
    int64_t step = 0;
  };
  auto job = std::make_shared<Job>();
  job->point = Eigen::Vector3d(request->point().x(), request->point().y(), request->point().z());
  job->normal = Eigen::Vector3d(request->normal().x(), request->normal().y(), request->normal().z());
  job->field = request->field();
  if (absl::Status s = exporter::CheckSectionField(job->field); !s.ok()) {
    reactor->Finish(ToGrpcStatus(absl::Status(s.code(), absl::StrCat("request.", s.message()))));
    return reactor;
  }
  // The shape at a step boundary (and, for stiffness, the design's
  // samples), then the materials' means and the cut off the loop.
  session->loop().Query([this, reactor, response, job](const SimCore* core) {
    if (core == nullptr) {
      reactor->Finish(ToGrpcStatus(absl::UnavailableError("the session is closed")));
      return;
    }
    job->solid = core->shared_solid();
    job->positions = job->solid->control_positions();
    job->rest = job->solid->discretization().control().positions();
    job->step = core->steps();
    if (job->field == "stiffness") job->design = job->solid->SaveDesign();
    OnBuilds(reactor, [reactor, response, job] {
      std::optional<exporter::MaterialFields> materials;
      if (job->design.has_value()) {
        absl::StatusOr<exporter::MaterialFields> m =
            exporter::MaterialFieldsOf(job->solid->discretization(), *job->design);
        if (m.ok()) materials = *std::move(m);
      }
      exporter::SectionInput in{&job->solid->discretization(), job->positions, job->rest,
                                materials.has_value() ? &*materials : nullptr};
      absl::StatusOr<exporter::Section> cut = exporter::CutSection(in, job->point, job->normal, job->field);
      if (!cut.ok()) {
        reactor->Finish(ToGrpcStatus(absl::Status(cut.status().code(),
                                                  absl::StrCat("request.", cut.status().message()))));
        return;
      }
      // A reply must fit in one message (4 MiB by default): a cut through a
      // solid of a million cells could be larger.
      constexpr size_t kMaxSectionFloats = 3u << 18;  // 3 MiB of floats, values included
      if (cut->positions.size() + cut->values.size() > kMaxSectionFloats) {
        reactor->Finish(ToGrpcStatus(absl::ResourceExhaustedError(absl::StrCat(
            "the section cuts ", cut->cells_cut, " cells into ", cut->values.size() / 3,
            " triangles, more than one reply carries; cut a smaller solid or level"))));
        return;
      }
      response->set_step(job->step);
      response->mutable_positions()->Assign(cut->positions.begin(), cut->positions.end());
      response->mutable_values()->Assign(cut->values.begin(), cut->values.end());
      response->set_field(cut->field);
      response->set_unit(cut->unit);
      response->set_min(cut->min);
      response->set_max(cut->max);
      response->set_cells_cut(cut->cells_cut);
      reactor->Finish(grpc::Status::OK);
    });
  });
  return reactor;
}

grpc::ServerUnaryReactor* SessionsService::GetCommandLog(grpc::CallbackServerContext* context,
                                                         const CommandLogRequest* request,
                                                         CommandLog* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  std::shared_ptr<const SolidSession> session = SessionOrFinish(request->session(), reactor);
  if (session == nullptr) return reactor;
  if (session->dir().empty()) {
    reactor->Finish(ToGrpcStatus(absl::FailedPreconditionError(
        "this server runs without --data_dir: it keeps no journal to list")));
    return reactor;
  }
  // Reading the journal can take a while: off the RPC threads.
  OnBuilds(reactor, [session, request, response, reactor] {
    // The durable prefix: a record being appended right now is a torn tail
    // to this reader, and its answer has not been sent yet.
    absl::StatusOr<JournalContents> journal = ReadJournal(session->dir() + "/journal", 0);
    if (!journal.ok()) {
      reactor->Finish(ToGrpcStatus(journal.status()));
      return;
    }
    response->set_records(static_cast<int64_t>(journal->records.size()));
    persist::JournalRecord record;
    for (const std::string& payload : journal->records) {
      if (!record.ParseFromString(payload)) {
        reactor->Finish(ToGrpcStatus(absl::DataLossError(
            absl::StrCat("session ", session->id(), ": a journal record does not parse"))));
        return;
      }
      if (!request->client_id().empty() && record.client_id() != request->client_id()) continue;
      CommandLogEntry* e = response->add_entries();
      e->set_client_id(record.client_id());
      e->set_seq(record.seq());
      e->set_step(record.step());
      e->set_code(record.reply().code());
      const google::protobuf::FieldDescriptor* f =
          Command::descriptor()->FindFieldByNumber(record.command().kind_case());
      e->set_kind(f != nullptr ? f->name() : "none");
    }
    reactor->Finish(grpc::Status::OK);
  });
  return reactor;
}

}  // namespace dynsolid::server
