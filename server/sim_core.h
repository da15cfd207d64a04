// The deterministic heart of a session: a solid::Solid plus what decides
// its future besides the solid itself (paused / steps remaining, the
// per-client answer caches). It applies commands and steps; it knows no
// clock, thread, gRPC or file, so the live simulation loop and the
// journal replay after a crash run exactly the same code and reach the
// same bits.
//
// Not thread-safe: owned and used by one thread (the session's simulation
// thread, or the recovery code before that thread starts).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "absl/container/flat_hash_map.h"
#include "absl/status/status.h"
#include "dynsolid/journal.pb.h"
#include "dynsolid/service.pb.h"
#include "server/history.h"
#include "server/surface_codec.h"
#include "solver/solid/solid.h"

namespace dynsolid::server {

struct CoreOptions {
  // Answers remembered per client for resends (the most recent ones).
  int answer_cache = 256;
  // Whether Save can work (the session has a data directory).
  bool can_save = false;
  // Bytes the undo histories may hold (history.h); the oldest entries go
  // first. Part of the session's determinism: recover with the same.
  int64_t undo_bytes = int64_t{256} << 20;
};

// Builds a solid of the session: its own scene (`edited` null: the scene
// the session was created from, with its levels and files) or an edited
// one (a topology edit's scene, self-contained). Used to undo across a
// topology edit and to recover a snapshot taken after one.
using SolidFactory =
    std::function<absl::StatusOr<std::shared_ptr<solid::Solid>>(const Scene* edited)>;

class SimCore {
 public:
  // `scene`: the scene `solid` was built from (topology edits start from
  // it); `factory` rebuilds solids (see SolidFactory; may be null in tests
  // that make no topology edit).
  SimCore(std::shared_ptr<solid::Solid> solid, CoreOptions options, bool start_paused,
          Scene scene = Scene(), SolidFactory factory = nullptr);
  SimCore(const SimCore&) = delete;
  SimCore& operator=(const SimCore&) = delete;

  enum class Outcome {
    kApplied,    // accepted and applied: record it
    kRejected,   // refused with a reason, nothing changed: record it
    kDuplicate,  // (client_id, seq) answered before: reply is that answer
    kUnknown,    // an old seq with no answer kept: not recorded
  };

  // A solid built ahead for a command that needs one (Prebuild).
  struct Prebuilt;

  // Applies (or refuses) one command at the current step boundary and fills
  // `reply` (applied_step = steps()). client_id and seq must already be
  // valid (CheckCommandEnvelope). Deterministic; with `prebuilt` (from
  // Prebuild for this request, with nothing applied in between) the result
  // is the same, bit for bit, only the expensive part is already done.
  Outcome Process(const CommandRequest& request, CommandReply* reply,
                  std::shared_ptr<Prebuilt> prebuilt = nullptr);

  // ---- Building off the loop. A topology edit, and an undo or redo into
  // another topology, build a new solid (hundreds of ms); a paint builds
  // the solid's new material (tens to hundreds of ms). NeedsBuild says
  // whether `request` is such a new command; Prebuild returns the build to
  // run on another thread while the loop goes on stepping. The caller must
  // apply no other command until it hands the result to Process (the build
  // reads the current solid's materials and topology, and the history),
  // except those MayPassBuild allows.
  bool NeedsBuild(const CommandRequest& request) const;

  // Whether `command` may be applied while the build for `building` (a
  // command NeedsBuild said yes to) is under way, ahead of it: true only
  // when that build is a paint's, an edit's or an unfix's and `command`
  // changes nothing such a build reads or installs (loads, drags, curves,
  // gravity; not materials, topology, constraints, the history or the
  // clock). So the build's result does not depend on whether `command`
  // went first, and a replay in the journal's order, where the build runs
  // in line, reaches the same bits. The build's command then finds loads
  // it did not see built: an edit carries them across, a paint and an
  // unfix leave them alone. The caller keeps each client's commands in
  // order.
  static bool MayPassBuild(const Command& building, const Command& command);

  // The last seq applied for `client_id` (0: none).
  uint64_t LastSeq(const std::string& client_id) const;
  std::function<std::shared_ptr<Prebuilt>()> Prebuild(const CommandRequest& request) const;
  // Fills in what `request` leaves to the server, at the step it is taken
  // (before Prebuild, on the simulation thread): a bake's rest positions,
  // the solid's control positions now. The journal records the filled
  // request, so a replay bakes the very same shape.
  void Stamp(CommandRequest& request) const;
  static void FillBake(const solid::Solid& solid, Bake& bake);

  // Whether the loop should take a step now: running, or a Step count left.
  bool WantsStep() const { return !paused_ || steps_remaining_ > 0; }
  // One Solid::Step and the loop bookkeeping (a Step count running out
  // pauses; a failed step pauses and sets last_error). Returns the step's
  // status.
  absl::Status StepOnce();

  // ---- Replay of a journal record: steps until the record's step (each
  // of which must be wanted, or DataLoss), then processes the command and
  // checks the outcome matches the journaled reply (DataLoss otherwise).
  absl::Status Replay(const persist::JournalRecord& record);

  // ---- Snapshots: the loop state and answer caches (the solid's state is
  // solid().SaveState(), stored beside them).
  void SaveTo(persist::Snapshot* snapshot) const;
  // Restores what SaveTo wrote (and the solid from snapshot.solid_state).
  // On error nothing changed.
  absl::Status RestoreFrom(const persist::Snapshot& snapshot);

  // The solid may be replaced by a topology edit, undo or redo: do not keep
  // references across Process calls.
  solid::Solid& solid() { return *solid_; }
  // The same, shared: for work on another thread that must keep it alive.
  std::shared_ptr<solid::Solid> shared_solid() const { return solid_; }
  const solid::Solid& solid() const { return *solid_; }
  int64_t steps() const { return solid_->steps(); }
  bool paused() const { return paused_; }
  int64_t steps_remaining() const { return steps_remaining_; }
  const std::string& last_error() const { return last_error_; }
  int64_t fields_version() const { return fields_version_; }
  int64_t commands_applied() const { return applied_; }
  int64_t commands_rejected() const { return rejected_; }
  const UndoHistory& history() const { return history_; }
  // Everyone's undo entries (InspectRequest.history).
  void DescribeHistory(HistoryInfo* out) const { history_.Describe(out); }
  // The scene of the current solid (the session's own until a topology edit).
  const Scene& scene() const { return *scene_; }
  // Wall time the last command held the loop, ms.
  double last_hold_ms() const { return last_hold_ms_; }
  // Set by a Save command; the loop writes the snapshot and clears it.
  bool TakeSaveRequest() {
    const bool s = save_requested_;
    save_requested_ = false;
    return s;
  }

  // The client that added load or constraint `id` (its command's
  // client_id), or "" for the scene's own items and ids it no longer
  // knows: the owners of the active items and of at least the kKeptOwners
  // newest removed ones are kept (an undo may bring those back).
  const std::string& owner(int64_t id) const;
  static constexpr size_t kKeptOwners = 2048;
  // The active loads and constraints with their owners, and the gravity
  // (InspectRequest.loads): fills reply.loads, constraints and gravity.
  void DescribeLoads(InspectReply* reply) const;

  // The surface connectivity (rebuilt when the solid's topology changes).
  std::shared_ptr<const SurfaceTopology> Topology();
  // A snapshot of the surface at the current step; fields only if asked.
  std::shared_ptr<const SurfaceSnapshot> MakeSnapshot(bool with_fields);

 private:
  struct Client {
    uint64_t last_seq = 0;
    std::deque<CommandReply> replies;  // most recent last
  };
  absl::Status Apply(const Command& command, CommandReply* reply, Prebuilt* prebuilt);
  absl::Status ApplyEdit(const TopologyEdit& edit, CommandReply* reply, Prebuilt* prebuilt);

  // ---- Per-person undo (sim_core_undo.cc; history.h says the design).
  // What a command's entry needs from before it is applied.
  struct Before {
    std::optional<solid::Solid::LoadInfo> load;              // remove_load
    std::optional<solid::Solid::ConstraintInfo> constraint;  // unfix
    Vec3 gravity;                                            // set_gravity
    std::shared_ptr<const std::string> material;             // paint
    TopologyEdit edit;                                       // edit (a bake filled in)
    std::string state;                                       // revert_to_scene
    std::shared_ptr<const Scene> scene;                      // edit, revert_to_scene
  };
  std::unique_ptr<Before> CaptureBefore(const Command& command) const;
  // Records an applied command in its client's history (a drag's release
  // in the drag's entry).
  absl::Status Record(const CommandRequest& request, const Before& before,
                      const CommandReply& reply);
  // The sender's own undo or redo; on error nothing changed.
  absl::Status UndoRedo(bool undo, const std::string& client, CommandReply* reply);
  absl::Status CheckChange(const persist::UndoEntry& entry, const persist::UndoChange& change,
                           bool undo, const std::string& client) const;
  absl::Status ApplyChange(const persist::UndoEntry& entry, persist::UndoChange& change,
                           bool undo, const std::string& client, bool* did);
  absl::Status UndoEdit(const persist::UndoEntry& entry, const persist::EditChange& change,
                        const std::string& client);
  absl::Status RedoEdit(const persist::UndoEntry& entry, const persist::EditChange& change,
                        const std::string& client);
  absl::Status PutBackState(const persist::RevertChange& change);
  // The session's own scene again, the clock going on.
  absl::Status RevertToScene();
  // Re-adds a load or pin an entry names; the new id is aliased.
  absl::Status AddBack(const persist::UndoChange& change, int64_t id);
  bool HasLoad(int64_t id) const;
  bool HasPin(int64_t id) const;
  // "cannot undo \"x\": " and the refusal.
  static std::string Refusal(bool undo, const persist::UndoEntry& entry);
  void Remember(Client& client, const CommandReply& reply);
  // Records the owner of the item an applied command added (if it added
  // one) and forgets the oldest owners of removed items beyond kKeptOwners.
  void RecordOwner(const std::string& client_id, const CommandReply& reply);

  std::shared_ptr<solid::Solid> solid_;
  const CoreOptions options_;
  bool paused_;
  int64_t steps_remaining_ = 0;
  std::string last_error_;
  int64_t fields_version_ = 0;
  int64_t applied_ = 0;
  int64_t rejected_ = 0;
  bool save_requested_ = false;
  absl::flat_hash_map<std::string, Client> clients_;
  // Load or constraint id -> the client_id of the command that added it.
  absl::flat_hash_map<int64_t, std::string> owners_;
  std::shared_ptr<const SurfaceTopology> topology_;
  std::shared_ptr<const Scene> original_;  // the session's own scene
  std::shared_ptr<const Scene> scene_;     // the current solid's
  SolidFactory factory_;
  UndoHistory history_;
  double last_hold_ms_ = 0;
};

// The client id of the server's own commands: the release of a drag or
// curve whose command stream ended (session_loop.cc). Clients may not use
// ids starting with "server:".
inline constexpr char kReleaseClient[] = "server:release";

// Stateless checks of a command's envelope, done when it arrives:
// client_id 1..64 characters without control characters, not starting
// with "server:", seq >= 1.
// InvalidArgument naming the field.
absl::Status CheckCommandEnvelope(const CommandRequest& request);
// A client_id's characters (also WatchRequest.client_id, which may be
// empty): at most 64, no control characters. InvalidArgument naming it.
absl::Status CheckClientIdCharacters(const std::string& id);

}  // namespace dynsolid::server
