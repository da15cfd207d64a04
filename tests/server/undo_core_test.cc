// Per-person undo in a session's core (server/history.h): each
// client undoes its own actions, applied to the solid as it is now; a
// stroke and a drag are one action each; conflicts are refused with the
// state unchanged; undo a lot then redo it all and the design is the same;
// the journal and snapshots replay it bit for bit.
#include <map>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "absl/strings/str_cat.h"
#include "google/protobuf/text_format.h"
#include "server/material_diff.h"
#include "server/sim_core.h"
#include "tests/server/test_core.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;

struct Live {
  TestCore t;
  std::map<std::string, uint64_t> seqs;
  std::vector<persist::JournalRecord> journal;
};

Live Make(bool paused = true) { return Live{MakeTestCore("block3", 1, paused), {}, {}}; }

CommandReply Send(Live& s, const std::string& client, const std::string& text,
                  uint64_t gesture = 0) {
  CommandRequest r;
  r.set_client_id(client);
  r.set_seq(++s.seqs[client]);
  EXPECT_TRUE(google::protobuf::TextFormat::ParseFromString(text, r.mutable_command())) << text;
  r.mutable_command()->set_gesture(gesture);
  s.t.core->Stamp(r);
  persist::JournalRecord rec;
  rec.set_step(s.t.core->steps());
  rec.set_client_id(client);
  rec.set_seq(r.seq());
  *rec.mutable_command() = r.command();
  CommandReply reply;
  s.t.core->Process(r, &reply);
  *rec.mutable_reply() = reply;
  s.journal.push_back(rec);
  return reply;
}

void Ok(const CommandReply& r) { ASSERT_EQ(r.code(), 0) << r.message(); }

void Steps(Live& s, int n) {
  for (int i = 0; i < n; ++i) ASSERT_OK(s.t.core->StepOnce());
}

int Cells(const Live& s) { return s.t.core->solid().discretization().control().num_cells(); }

// The boundary face of the current control mesh nearest x.
int32_t Face(const Live& s, const Eigen::Vector3d& x) {
  const mesh::CellComplex& c = s.t.core->solid().discretization().control();
  int32_t best = -1;
  double d = 1e300;
  for (int32_t f = 0; f < c.num_faces(); ++f) {
    if (!c.face_is_boundary(f)) continue;
    const double e = (c.FaceCentroid(f) - x).squaredNorm();
    if (e < d) {
      d = e;
      best = f;
    }
  }
  return best;
}

std::string Extrude(const Live& s, const Eigen::Vector3d& x, double distance) {
  return absl::StrCat("edit { extrude_faces { faces: ", Face(s, x), " distance: ", distance,
                      " } }");
}

// Per element, its material samples.
std::vector<std::vector<double>> Materials(const Live& s) {
  absl::StatusOr<ElementMaterials> m =
      ParseMaterialSection(*s.t.core->solid().SaveStateParts().section);
  EXPECT_OK(m);
  std::vector<std::vector<double>> out;
  for (int32_t a : m->element_array) out.push_back(m->arrays[a]);
  return out;
}

// What a person designed, ids aside: the control mesh at rest, the
// materials, the loads, pins and gravity.
std::string Design(const Live& s) {
  const solid::Solid& solid = s.t.core->solid();
  const mesh::CellComplex& c = solid.discretization().control();
  std::string out = absl::StrCat("cells ", c.num_cells(), " vertices ", c.num_vertices(), "\n");
  for (int64_t i = 0; i < c.positions().size(); ++i) absl::StrAppend(&out, c.positions().data()[i], " ");
  absl::StrAppend(&out, "\nmaterials:");
  for (const auto& m : Materials(s)) {
    for (double v : m) absl::StrAppend(&out, " ", v);
    absl::StrAppend(&out, ";");
  }
  absl::StrAppend(&out, "\nloads:");
  for (const solid::Solid::LoadInfo& l : solid.ActiveLoads()) {
    absl::StrAppend(&out, " kind ", static_cast<int>(l.kind), " p ", l.pascals, " f ",
                    l.force.x(), ",", l.force.y(), ",", l.force.z(), " ",
                    l.region.ShortDebugString());
    for (const auto& x : l.material_points) absl::StrAppend(&out, " at ", x.x(), ",", x.y(), ",", x.z());
  }
  absl::StrAppend(&out, "\npins:");
  for (const solid::Solid::ConstraintInfo& k : solid.ActiveConstraints()) {
    absl::StrAppend(&out, " ", k.region.ShortDebugString(), " n ", k.control_points.size());
  }
  const Eigen::Vector3d g = solid.gravity();
  absl::StrAppend(&out, "\ngravity ", g.x(), ",", g.y(), ",", g.z(), "\n");
  return out;
}

constexpr char kForce[] = "add_point_force { position { x: 1.5 y: 1.5 z: 2 } force { z: -50 } }";
constexpr char kPin[] = "fix_region { box { min { x: -0.1 y: -0.1 z: -0.1 } max { x: 3.1 y: 3.1 z: 0.1 } } }";
std::string Paint(double x, double y, double z, double young = 4e5) {
  return absl::StrCat("paint_material { region { sphere { center { x: ", x, " y: ", y, " z: ", z,
                      " } radius: 0.6 } } material { young_modulus: ", young,
                      " } strength: 1 falloff: 0.3 }");
}

TEST(UndoCoreTest, TwoClientsEachUndoTheirOwnActionInBothOrders) {
  for (const bool alice_first : {true, false}) {
    SCOPED_TRACE(alice_first ? "alice first" : "bob first");
    Live s = Make();
    const std::vector<std::vector<double>> fresh = Materials(s);
    Ok(Send(s, "alice", Extrude(s, {1.5, 1.5, 3}, 0.5)));
    Ok(Send(s, "bob", kForce));
    Ok(Send(s, "bob", Paint(0.5, 0.5, 0.5)));
    Steps(s, 5);
    ASSERT_EQ(Cells(s), 28);
    const std::vector<std::vector<double>> painted = Materials(s);
    auto undo_alice = [&] {
      const Points p = s.t.core->solid().control_positions();
      const CommandReply u = Send(s, "alice", "undo {}");
      Ok(u);
      EXPECT_THAT(u.history().what(), HasSubstr("extrude face"));
      EXPECT_EQ(u.history().undo_depth(), 0);
      EXPECT_EQ(u.history().redo_depth(), 1);
      EXPECT_EQ(Cells(s), 27);
      // Not rewound: the 64 control points it kept are where they were.
      EXPECT_EQ(s.t.core->solid().control_positions(), p.topRows(64));
    };
    auto undo_bob = [&] {
      const Points p = s.t.core->solid().control_positions();
      const int cells = Cells(s);
      Ok(Send(s, "bob", "undo {}"));  // the paint
      const CommandReply u = Send(s, "bob", "undo {}");  // the force
      Ok(u);
      EXPECT_EQ(u.history().what(), "point force");
      EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty());
      EXPECT_EQ(Cells(s), cells);  // alice's work stays
      EXPECT_EQ(s.t.core->solid().control_positions(), p);
    };
    if (alice_first) {
      undo_alice();
      // Bob's paint and force stay.
      EXPECT_EQ(s.t.core->solid().ActiveLoads().size(), 1u);
      EXPECT_EQ(Materials(s).size(), fresh.size());
      EXPECT_NE(Materials(s), fresh);
      undo_bob();
    } else {
      undo_bob();
      EXPECT_EQ(Cells(s), 28);
      EXPECT_NE(Materials(s), painted);
      undo_alice();
    }
    EXPECT_EQ(Materials(s), fresh);
    // And nothing more to undo, for either: undo is each person's own.
    const CommandReply none = Send(s, "alice", "undo {}");
    EXPECT_EQ(none.code(), static_cast<int>(absl::StatusCode::kFailedPrecondition));
    EXPECT_THAT(none.message(), HasSubstr("you have nothing to undo"));
    Steps(s, 5);
    EXPECT_EQ(s.t.core->last_error(), "");
  }
}

TEST(UndoCoreTest, AnUndoThatOthersBuiltOnIsRefusedNamingTheConflictAndChangesNothing) {
  Live s = Make();
  Ok(Send(s, "alice", Extrude(s, {1.5, 1.5, 3}, 0.5)));
  // Bob extrudes the top of alice's new cell: his cell stands on hers.
  Ok(Send(s, "bob", Extrude(s, {1.5, 1.5, 3.5}, 0.5)));
  Steps(s, 3);
  ASSERT_EQ(Cells(s), 29);
  const std::string state = s.t.core->solid().SaveState();
  persist::Snapshot before;
  s.t.core->SaveTo(&before);
  const CommandReply u = Send(s, "alice", "undo {}");
  EXPECT_EQ(u.code(), static_cast<int>(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(u.message(), HasSubstr("cannot undo \"extrude face"));
  EXPECT_THAT(u.message(), HasSubstr("another person (bob): \"extrude face"));
  EXPECT_THAT(u.message(), HasSubstr("has to be undone first"));
  EXPECT_THAT(u.message(), HasSubstr("Nothing changed"));
  EXPECT_EQ(s.t.core->solid().SaveState(), state);
  EXPECT_EQ(Cells(s), 29);
  persist::Snapshot after;
  s.t.core->SaveTo(&after);
  EXPECT_EQ(after.undo_history().SerializeAsString(), before.undo_history().SerializeAsString());
  // Once bob took his back, alice's goes.
  Ok(Send(s, "bob", "undo {}"));
  Ok(Send(s, "alice", "undo {}"));
  EXPECT_EQ(Cells(s), 27);
}

TEST(UndoCoreTest, AStrokeOfTwentyDabsIsOneEntryUndoneInOneStep) {
  Live s = Make();
  const std::vector<std::vector<double>> fresh = Materials(s);
  Ok(Send(s, "alice", kPin));
  const size_t pins = s.t.core->solid().constraint_ids().size();  // the scene's and alice's
  for (int i = 0; i < 20; ++i) Ok(Send(s, "paul", Paint(0.2 + 0.13 * i, 1.5, 3, 4e5 + 1e4 * i), 77));
  // Another person's commands in between do not split it.
  HistoryInfo h;
  s.t.core->DescribeHistory(&h);
  ASSERT_EQ(h.entries_size(), 2);
  EXPECT_EQ(h.entries(1).what(), "stiffness stroke, 20 dabs");
  EXPECT_EQ(h.entries(1).client_id(), "paul");
  EXPECT_EQ(h.entries(0).what(), "pin");
  const CommandReply u = Send(s, "paul", "undo {}");
  Ok(u);
  EXPECT_EQ(u.history().what(), "stiffness stroke, 20 dabs");
  EXPECT_EQ(u.history().undo_depth(), 0);
  EXPECT_EQ(Materials(s), fresh);
  EXPECT_EQ(s.t.core->solid().constraint_ids().size(), pins);  // alice's pin stays
  // Redo: the whole stroke again; a new gesture is a new entry.
  Ok(Send(s, "paul", "redo {}"));
  EXPECT_NE(Materials(s), fresh);
  Ok(Send(s, "paul", Paint(1.5, 1.5, 0, 7e5), 78));
  HistoryInfo after;
  s.t.core->DescribeHistory(&after);
  ASSERT_EQ(after.entries_size(), 3);
  EXPECT_EQ(after.entries(1).what(), "stiffness stroke, 20 dabs");
  EXPECT_EQ(after.entries(2).what(), "stiffness paint");
}

TEST(UndoCoreTest, AReleasedDragUndoneDoesNotPullAgain) {
  Live s = Make(/*paused=*/false);
  const CommandReply d = Send(s, "dora", R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
      target { x: 1.5 y: 1.5 z: 3 } stiffness: 2e4 })");
  Ok(d);
  for (double z : {3.1, 3.2, 3.3}) {
    Ok(Send(s, "dora", absl::StrCat("move_drag { load_id: ", d.load_id(),
                                    " target { x: 1.5 y: 1.5 z: ", z, " } }")));
    Steps(s, 10);
  }
  // The stream ended: the server released it.
  Ok(Send(s, kReleaseClient, absl::StrCat("remove_load { load_id: ", d.load_id(), " }")));
  HistoryInfo h;
  s.t.core->DescribeHistory(&h);
  ASSERT_EQ(h.entries_size(), 1);  // press to release: one entry, no move, no release
  EXPECT_EQ(h.entries(0).what(), "drag");
  const CommandReply u = Send(s, "dora", "undo {}");
  Ok(u);
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty()) << "no drag came back";
  const CommandReply r = Send(s, "dora", "redo {}");
  Ok(r);
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty()) << "nor on redo";
  // A drag still held is let go by its undo.
  const CommandReply d2 = Send(s, "dora", R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
      target { x: 1.5 y: 1.5 z: 3.2 } stiffness: 2e4 })");
  Ok(d2);
  Steps(s, 5);
  Ok(Send(s, "dora", "undo {}"));
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty());
  Ok(Send(s, "dora", "redo {}"));
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty());
  Steps(s, 20);
  EXPECT_EQ(s.t.core->last_error(), "");
}

// An inflate held and let go (the viewer sends both with one gesture) is
// one entry; its undo and redo leave no pressure that nobody holds.
TEST(UndoCoreTest, AHeldPressureReleasedIsOneEntryAndItsUndoPutsNoLoadBack) {
  Live s = Make(/*paused=*/false);
  const CommandReply p = Send(s, "ivy", R"(add_pressure { region { sphere {
      center { x: 1.5 y: 1.5 z: 3 } radius: 0.8 } } pascals: 3000 })", /*gesture=*/7);
  Ok(p);
  Steps(s, 20);
  Ok(Send(s, "ivy", absl::StrCat("remove_load { load_id: ", p.load_id(), " }"), 7));
  HistoryInfo h;
  s.t.core->DescribeHistory(&h);
  ASSERT_EQ(h.entries_size(), 1);
  EXPECT_EQ(h.entries(0).what(), "inflate, released");
  Ok(Send(s, "ivy", "undo {}"));
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty()) << "no pressure came back";
  Ok(Send(s, "ivy", "redo {}"));
  EXPECT_TRUE(s.t.core->solid().ActiveLoads().empty()) << "nor on redo";
}

// 50 actions of three people: loads, pins, paints and strokes, gravity,
// drags, edits, removals of each other's loads.
void Script(Live& s) {
  const char* who[] = {"ann", "ben", "cat"};
  int64_t force = 0, pin = 0;
  for (int i = 0; i < 50; ++i) {
    const std::string c = who[i % 3];
    CommandReply r;
    switch (i % 10) {
      case 0:
        r = Send(s, c, absl::StrCat("add_point_force { position { x: ", 0.3 + 0.05 * i,
                                    " y: 1.5 z: 1 } force { z: ", -10 - i, " } }"));
        force = r.load_id();
        break;
      case 1:
        r = Send(s, c, Paint(0.5, 0.5 + 0.03 * i, 0.5, 3e5 + 1e4 * i));
        break;
      case 2:
        for (int k = 0; k < 4; ++k) {
          r = Send(s, c, Paint(2.5, 0.3 + 0.4 * k, 0.5, 6e5 + 1e3 * i), 1000 + i);
          Ok(r);
        }
        break;
      case 3:
        r = Send(s, c, kPin);
        pin = r.constraint_id();
        break;
      case 4:
        r = Send(s, c, absl::StrCat("set_gravity { z: ", -1 - i * 0.1, " }"));
        break;
      case 5:
        r = Send(s, c, absl::StrCat("remove_load { load_id: ", force, " }"));
        break;
      case 6: {
        r = Send(s, c, R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
            target { x: 1.5 y: 1.6 z: 3.1 } stiffness: 1e4 })");
        Ok(r);
        const int64_t id = r.load_id();
        Ok(Send(s, c, absl::StrCat("move_drag { load_id: ", id, " target { x: 1.5 y: 1.7 z: 3.2 } }")));
        r = Send(s, c, absl::StrCat("remove_load { load_id: ", id, " }"));
        break;
      }
      case 7:
        // Columns on the top, one further each time.
        r = Send(s, c, Extrude(s, {0.5 + (i / 10) * 0.5, 2.5, 3}, 0.3));
        break;
      case 8:
        r = Send(s, c, absl::StrCat("unfix { constraint_id: ", pin, " }"));
        break;
      case 9:
        r = Send(s, c, "add_pressure { region { control_cells: 0 } pascals: 300 }");
        break;
    }
    Ok(r);
  }
}

TEST(UndoCoreTest, FigmasRuleUndoALotThenRedoItAllAndTheDesignIsUnchanged) {
  Live s = Make();
  Script(s);
  const std::string design = Design(s);
  // Undo the newest entry in effect, whoever's it is, 40 times.
  int undone = 0;
  for (; undone < 40; ++undone) {
    HistoryInfo h;
    s.t.core->DescribeHistory(&h);
    const HistoryEntryInfo* last = nullptr;
    for (const HistoryEntryInfo& e : h.entries()) {
      if (!e.undone()) last = &e;
    }
    ASSERT_NE(last, nullptr);
    const CommandReply u = Send(s, last->client_id(), "undo {}");
    ASSERT_EQ(u.code(), 0) << "undo " << undone << " (" << last->what() << "): " << u.message();
  }
  EXPECT_NE(Design(s), design);
  for (int k = 0; k < undone; ++k) {
    HistoryInfo h;
    s.t.core->DescribeHistory(&h);
    const HistoryEntryInfo* next = nullptr;
    for (const HistoryEntryInfo& e : h.entries()) {
      if (e.undone()) {
        next = &e;
        break;
      }
    }
    ASSERT_NE(next, nullptr);
    const CommandReply r = Send(s, next->client_id(), "redo {}");
    ASSERT_EQ(r.code(), 0) << "redo " << k << " (" << next->what() << "): " << r.message();
  }
  EXPECT_EQ(Design(s), design);
  Steps(s, 10);
  EXPECT_EQ(s.t.core->last_error(), "");
}

TEST(UndoCoreTest, HistoryListsEachPersonsEntriesAndRevertToTheSceneIsUndoable) {
  Live s = Make();
  const std::string fresh = Design(s);
  Ok(Send(s, "alice", absl::StrCat("edit { extrude_faces { faces: ", Face(s, {1.5, 1.5, 3}),
                                   " distance: 0.5 } }")));
  for (int i = 0; i < 12; ++i) Ok(Send(s, "alice", Paint(0.5, 0.5, 0.5 + 0.1 * i), 5));
  Ok(Send(s, "bob", kPin));
  const std::string designed = Design(s);
  HistoryInfo h;
  s.t.core->DescribeHistory(&h);
  ASSERT_EQ(h.entries_size(), 3);
  EXPECT_THAT(h.entries(0).what(), ::testing::MatchesRegex("extrude face [0-9]+"));
  EXPECT_EQ(h.entries(1).what(), "stiffness stroke, 12 dabs");
  EXPECT_EQ(h.entries(2).what(), "pin");
  ASSERT_EQ(h.people_size(), 2);
  EXPECT_EQ(h.people(0).client_id(), "alice");
  EXPECT_THAT(h.people(0).undo(), ::testing::ElementsAre(1, 2));
  EXPECT_THAT(h.people(1).undo(), ::testing::ElementsAre(3));

  Ok(Send(s, "carol", "revert_to_scene {}"));
  EXPECT_EQ(Design(s), fresh);
  // Alice's work is under the revert: refused until it is undone.
  const CommandReply refused = Send(s, "alice", "undo {}");
  EXPECT_EQ(refused.code(), static_cast<int>(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(refused.message(), HasSubstr("reverted to the scene after it"));
  const CommandReply u = Send(s, "carol", "undo {}");
  Ok(u);
  EXPECT_EQ(u.history().what(), "revert to the scene");
  EXPECT_EQ(Design(s), designed);
  Ok(Send(s, "alice", "undo {}"));
  Ok(Send(s, "alice", "undo {}"));
  EXPECT_EQ(Cells(s), 27);
  Ok(Send(s, "carol", "redo {}"));  // nothing of anyone's is on top of it
  EXPECT_EQ(Design(s), fresh);
}

// A fresh session given `journal`, stepped to `steps`: its state.
std::string Replayed(const std::vector<persist::JournalRecord>& journal, int64_t steps,
                     const persist::Snapshot* from = nullptr) {
  Live r = Make(/*paused=*/false);
  if (from != nullptr && !r.t.core->RestoreFrom(*from).ok()) return "restore failed";
  for (const persist::JournalRecord& rec : journal) {
    if (from != nullptr && rec.step() < from->step()) continue;
    const absl::Status st = r.t.core->Replay(rec);
    if (!st.ok()) return std::string(st.message());
  }
  while (r.t.core->steps() < steps) {
    if (!r.t.core->StepOnce().ok()) return "step failed";
  }
  return r.t.core->solid().SaveState();
}

TEST(UndoCoreTest, AJournalOfUndosReplaysToTheSameBitsFromTheStartAndFromASnapshot) {
  Live s = Make(/*paused=*/false);
  Ok(Send(s, "ann", Extrude(s, {1.5, 1.5, 3}, 0.4)));
  Steps(s, 3);
  for (int i = 0; i < 5; ++i) Ok(Send(s, "ben", Paint(0.5, 0.5 + 0.4 * i, 0.5), 9));
  Ok(Send(s, "ann", kForce));
  Steps(s, 4);
  Ok(Send(s, "ben", "undo {}"));
  // A snapshot here, then more, with a refused undo journaled too.
  persist::Snapshot snap;
  s.t.core->SaveTo(&snap);
  snap.set_solid_state(s.t.core->solid().SaveState());
  const size_t journaled = s.journal.size();
  Steps(s, 2);
  Ok(Send(s, "ben", Extrude(s, {1.5, 1.5, 3.4}, 0.3)));
  Steps(s, 2);
  Ok(Send(s, "ann", "undo {}"));  // the force
  EXPECT_NE(Send(s, "ann", "undo {}").code(), 0);  // the extrude: ben built on it
  // Ben's extrude cleared his redo list (the stroke is gone for good).
  EXPECT_NE(Send(s, "ben", "redo {}").code(), 0);
  Steps(s, 3);
  Ok(Send(s, "ben", "undo {}"));
  Ok(Send(s, "ann", "undo {}"));
  Ok(Send(s, "ann", "revert_to_scene {}"));
  Steps(s, 2);
  Ok(Send(s, "ann", "undo {}"));
  Steps(s, 5);
  const std::string want = s.t.core->solid().SaveState();
  EXPECT_EQ(Replayed(s.journal, s.t.core->steps()), want);
  std::vector<persist::JournalRecord> rest(s.journal.begin() + journaled, s.journal.end());
  EXPECT_EQ(Replayed(rest, s.t.core->steps(), &snap), want);
}

}  // namespace
}  // namespace dynsolid::server
