// Sculpting in a session's deterministic core (SimCore): topology edits,
// drags and curves, undo and redo across topology (undo_core_test has the
// per-person rules), refused edits that
// change nothing, and snapshots and journal replay that come back to the
// same bits. No network: SimCore is what the live loop and the recovery
// code both run.
#include <cmath>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "google/protobuf/text_format.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"
#include "tests/server/test_core.h"
#include "tests/testing/status_matchers.h"

namespace dynsolid::server {
namespace {

using ::testing::HasSubstr;

using Session = TestCore;

Session Make(const std::string& builtin = "block3", int levels = 1) {
  return MakeTestCore(builtin, levels, /*start_paused=*/false);
}

CommandReply Send(Session& s, const std::string& text, const std::string& client = "c") {
  return SendText(s, client, text);
}

int Cells(const Session& s) { return s.core->solid().discretization().control().num_cells(); }

// A moving, loaded block: a drag on the top and gravity.
void Stir(Session& s) {
  const CommandReply r = Send(s, R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
                                           target { x: 2.0 y: 1.5 z: 3.3 } stiffness: 2e4 })");
  ASSERT_EQ(r.code(), 0) << r.message();
  ASSERT_EQ(Send(s, "set_gravity { z: -9.81 }").code(), 0);
  Steps(s, 20);
}

TEST(SculptCoreTest, EveryTopologyToolChangesTheCellCountAsItSaysAndTheSolidGoesOn) {
  Session s = Make();
  Stir(s);
  ASSERT_EQ(Cells(s), 27);
  struct Case {
    const char* edit;
    int cells_after;
  } cases[] = {
      // Two columns, two layers each.
      {"extrude_faces { near { x: 0.5 y: 1.5 z: 3 } near { x: 2.5 y: 1.5 z: 3 } distance: 1 "
       "layers: 2 }",
       31},
      // A handle between the facing sides of their upper layers.
      {"merge_faces { near { x: 1 y: 1.5 z: 3.75 } near { x: 2 y: 1.5 z: 3.75 } }", 32},
      {"delete_cells { near { x: 0.5 y: 0.5 z: 2.5 } }", 31},
      // A hexahedron splits into 8.
      {"subdivide_cells { near { x: 1.5 y: 1.5 z: 0.5 } }", 38},
  };
  for (const Case& c : cases) {
    const CommandReply r = Send(s, absl::StrCat("edit { ", c.edit, " }"));
    ASSERT_EQ(r.code(), 0) << c.edit << ": " << r.message();
    EXPECT_EQ(r.edit().control_cells_after(), c.cells_after) << r.edit().summary();
    EXPECT_EQ(Cells(s), c.cells_after);
    EXPECT_FALSE(r.edit().summary().empty());
    EXPECT_GT(r.edit().elements_after(), 0);
    // The drag and gravity keep their place; it keeps simulating.
    EXPECT_EQ(r.edit().dropped_loads_size(), 0) << c.edit;
    Steps(s, 100);
    EXPECT_EQ(s.core->last_error(), "");
  }
  // Sharp edges: the topology stays, the subdivision rules change.
  const mesh::CellComplex& control = s.core->solid().discretization().control();
  const std::array<int32_t, 2> e = control.edge_vertices(0);
  const CommandReply r = Send(s, absl::StrCat("edit { sharp_edges { edges { v0: ", e[0],
                                              " v1: ", e[1], " } sharp: true } }"));
  ASSERT_EQ(r.code(), 0) << r.message();
  EXPECT_EQ(Cells(s), 38);
  // 1000 steps in all after the last edit without a failed step.
  Steps(s, 1000);
  EXPECT_EQ(s.core->last_error(), "");
  EXPECT_EQ(s.core->steps(), 20 + 400 + 1000);
}

// Undo of an edit puts the control mesh back without rewinding the solid
// (server/history.h): the points the edit kept stay where they are now.
TEST(SculptCoreTest, UndoAndRedoOfATopologyEditPutTheMeshBackAndTheClockGoesOn) {
  Session s = Make();
  Stir(s);
  const Points rest_before = s.core->solid().discretization().control().positions();
  const int64_t version = s.core->solid().topology_version();
  ASSERT_EQ(Send(s, "edit { extrude_faces { near { x: 0.5 y: 1.5 z: 3 } distance: 0.4 } }").code(),
            0);
  EXPECT_EQ(Cells(s), 28);
  EXPECT_GT(s.core->solid().topology_version(), version);
  Steps(s, 30);
  const Points p_edited = s.core->solid().control_positions();
  const double t_edited = s.core->solid().time();

  CommandReply u = Send(s, "undo {}");
  ASSERT_EQ(u.code(), 0) << u.message();
  EXPECT_EQ(u.history().what(), "extrude 1 face");
  EXPECT_EQ(u.history().undo_depth(), 2);  // the drag and the gravity remain
  EXPECT_EQ(u.history().redo_depth(), 1);
  EXPECT_EQ(Cells(s), 27);
  EXPECT_EQ(s.core->solid().discretization().control().positions(), rest_before);
  EXPECT_EQ(s.core->solid().control_positions(), p_edited.topRows(64));  // not rewound
  EXPECT_EQ(s.core->solid().time(), t_edited);                // the clock goes on
  EXPECT_EQ(s.core->solid().steps(), 50);
  EXPECT_GT(s.core->solid().topology_version(), version);     // watchers see a new topology

  CommandReply r = Send(s, "redo {}");
  ASSERT_EQ(r.code(), 0) << r.message();
  EXPECT_EQ(Cells(s), 28);
  EXPECT_EQ(s.core->solid().control_positions().topRows(64), p_edited.topRows(64));
  ASSERT_EQ(Send(s, "undo {}").code(), 0);
  EXPECT_EQ(Cells(s), 27);
  Steps(s, 5);
  EXPECT_EQ(s.core->last_error(), "");
}

TEST(SculptCoreTest, UndoWalksBackThroughEveryUndoableCommandAndANewCommandClearsRedo) {
  Session s = Make();
  Steps(s, 5);
  const Points rest = s.core->solid().control_positions();
  ASSERT_EQ(Send(s, R"(paint_material { region { sphere { center { x: 1.5 y: 1.5 z: 3 }
      radius: 1 } } material { young_modulus: 5e5 density: 3000 damping: 100 } strength: 1 })")
                .code(),
            0);
  ASSERT_EQ(Send(s, "edit { subdivide_cells { cells: 13 } }").code(), 0);
  ASSERT_EQ(Send(s, R"(curve { material_points { x: 0 y: 1.5 z: 3 } material_points { x: 3 y: 1.5 z: 3 }
      targets { x: 0 y: 1.5 z: 3.2 } targets { x: 3 y: 1.5 z: 3.2 } stiffness: 1e4 })")
                .code(),
            0);
  Steps(s, 10);
  EXPECT_EQ(s.core->history().undo_depth(), 3);
  for (int i = 0; i < 3; ++i) ASSERT_EQ(Send(s, "undo {}").code(), 0);
  EXPECT_EQ(Cells(s), 27);
  EXPECT_TRUE(s.core->solid().ActiveLoads().empty());  // the curve let go
  (void)rest;
  const CommandReply none = Send(s, "undo {}");
  EXPECT_EQ(none.code(), static_cast<int>(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(none.message(), HasSubstr("command.undo: you have nothing to undo"));
  ASSERT_EQ(Send(s, "redo {}").code(), 0);
  EXPECT_EQ(s.core->history().redo_depth(), 2);
  ASSERT_EQ(Send(s, "set_gravity { z: -1 }").code(), 0);
  EXPECT_EQ(s.core->history().redo_depth(), 0);
  EXPECT_THAT(Send(s, "redo {}").message(), HasSubstr("command.redo: you have nothing to redo"));
}

TEST(SculptCoreTest, RefusedEditsNameTheItemAndTheRuleAndChangeNothing) {
  Session s = Make();
  Stir(s);
  const std::string state = s.core->solid().SaveState();
  const int undo = s.core->history().undo_depth();
  std::string all;
  for (int c = 0; c < 27; ++c) absl::StrAppend(&all, " cells: ", c);
  struct Case {
    std::string edit, message;
  } cases[] = {
      {"delete_cells {" + all + " }", "edit.delete_cells"},
      {"delete_cells { cells: 99 }", "edit.delete_cells.cells[0]: cell 99 is out of range"},
      {"extrude_faces { faces: 0 faces: 0 distance: 1 }", "edit.extrude_faces"},
      {"extrude_faces { near { x: 1.5 y: 1.5 z: 3 } distance: -1 }", "edit.extrude_faces"},
      {"extrude_faces { near { x: 1.5 y: 1.5 z: 3 } distance: nan }", "nan"},
      {"merge_faces { near { x: 0.5 y: 0.5 z: 3 } near { x: 0.5 y: 0.5 z: 3 } }",
       "edit.merge_faces"},
      {"subdivide_cells { cells: -1 }", "edit.subdivide_cells.cells[0]"},
      {"sharp_edges { edges { v0: 0 v1: 63 } sharp: true }", "edit.sharp_edges"},
      {"", "edit: no edit kind is set"},
  };
  // An interior face: one with a cell on each side.
  const mesh::CellComplex& control = s.core->solid().discretization().control();
  int interior = 0;
  while (control.face_is_boundary(interior)) ++interior;
  const CommandReply r = Send(s, absl::StrCat("edit { extrude_faces { faces: ", interior,
                                              " distance: 0.5 } }"));
  EXPECT_EQ(r.code(), static_cast<int>(absl::StatusCode::kInvalidArgument));
  EXPECT_THAT(r.message(), HasSubstr(absl::StrCat("face ", interior, " is interior")));
  for (const Case& c : cases) {
    const CommandReply r = Send(s, absl::StrCat("edit { ", c.edit, " }"));
    EXPECT_EQ(r.code(), static_cast<int>(absl::StatusCode::kInvalidArgument)) << c.edit;
    EXPECT_THAT(r.message(), HasSubstr(c.message)) << c.edit;
    EXPECT_THAT(r.message(), ::testing::StartsWith("command.edit")) << c.edit;
  }
  EXPECT_EQ(s.core->solid().SaveState(), state);
  EXPECT_EQ(s.core->history().undo_depth(), undo);
  EXPECT_EQ(Cells(s), 27);
}

TEST(SculptCoreTest, DragTargetsWithinAStepFoldToTheLatestAndReleaseEndsTheDrag) {
  Session a = Make(), b = Make();
  int64_t id = 0;
  for (Session* s : {&a, &b}) {
    const CommandReply r = Send(*s, R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
                                          target { x: 1.5 y: 1.5 z: 3 } stiffness: 5e4 })");
    ASSERT_EQ(r.code(), 0) << r.message();
    id = r.load_id();
  }
  // a: three target updates in one step; b: only the last one.
  for (double z : {3.1, 3.2, 3.4}) {
    ASSERT_EQ(Send(a, absl::StrCat("move_drag { load_id: ", id, " target { x: 1.5 y: 1.5 z: ",
                                   z, " } }"))
                  .code(),
              0);
  }
  ASSERT_EQ(Send(b, absl::StrCat("move_drag { load_id: ", id,
                                 " target { x: 1.5 y: 1.5 z: 3.4 } }"))
                .code(),
            0);
  Steps(a, 40);
  Steps(b, 40);
  EXPECT_EQ(a.core->solid().control_positions(), b.core->solid().control_positions());
  EXPECT_GT(a.core->solid().TracedPositions()[0].z(), 3.0 + 1e-4);  // pulled up
  // Move targets are not undoable: undo takes back the drag itself.
  EXPECT_EQ(a.core->history().undo_depth(), 1);
  const CommandReply bad = Send(a, "move_drag { load_id: 77 target { x: 0 y: 0 z: 0 } }");
  EXPECT_EQ(bad.code(), static_cast<int>(absl::StatusCode::kNotFound)) << bad.message();
  EXPECT_THAT(bad.message(), HasSubstr("77"));
  ASSERT_EQ(Send(a, absl::StrCat("remove_load { load_id: ", id, " }")).code(), 0);
  EXPECT_TRUE(a.core->solid().load_ids().empty());
}

// A fresh block3 session given `journal` and stepped to `steps`: its state.
std::string ReplayedState(const std::vector<persist::JournalRecord>& journal, int64_t steps) {
  Session replayed = Make();
  for (const persist::JournalRecord& rec : journal) {
    if (!replayed.core->Replay(rec).ok()) return "replay failed";
  }
  while (replayed.core->steps() < steps) {
    if (!replayed.core->StepOnce().ok()) return "step failed";
  }
  return replayed.core->solid().SaveState();
}

// Bake: the shape at the step the command is taken becomes the rest shape
// (the server stamps it into the command, so the journal replays the same
// bake), built off the loop while the solid steps on; the velocities are
// zero, the drag and the pins stay on their points, and with no load the
// baked solid stays where it was. Undo comes back bit for bit.
TEST(SculptCoreTest, BakeMakesTheShapeTheRestShapeOffTheLoopAndUndoes) {
  Session s = Make();
  const CommandReply d = Send(s, R"(drag { material_point { x: 1.5 y: 1.5 z: 3 }
                                           target { x: 2.1 y: 1.5 z: 3.3 } stiffness: 2e4 })");
  ASSERT_EQ(d.code(), 0) << d.message();
  Steps(s, 400);
  const std::string before = s.core->solid().SaveState();
  const int fixed = s.core->solid().build_report().fixed_control_points;
  ASSERT_GT(fixed, 0);

  CommandRequest req;
  req.set_client_id("c");
  req.set_seq(++s.seq);
  req.mutable_command()->mutable_edit()->mutable_bake();
  s.core->Stamp(req);
  const Points shape = s.core->solid().control_positions();
  ASSERT_EQ(req.command().edit().bake().rest_positions_size(), shape.size());
  auto job = s.core->Prebuild(req);
  auto prebuilt = job();
  Steps(s, 3);  // the live loop goes on while it builds
  const Points at_apply = s.core->solid().control_positions();
  CommandReply reply;
  s.core->Process(req, &reply, prebuilt);
  ASSERT_EQ(reply.code(), 0) << reply.message();
  EXPECT_THAT(reply.edit().summary(), HasSubstr("baked the current shape"));
  EXPECT_EQ(s.core->solid().control_positions(), shape);  // the stamped shape, at rest
  EXPECT_EQ(s.core->solid().discretization().control().positions(), shape);
  EXPECT_EQ(s.core->solid().ComputeEnergies().kinetic, 0);
  EXPECT_EQ(s.core->solid().build_report().fixed_control_points, fixed);
  ASSERT_EQ(s.core->solid().load_ids().size(), 1u);  // the drag stays
  EXPECT_TRUE(reply.edit().dropped_loads().empty());
  EXPECT_TRUE(reply.edit().dropped_constraints().empty());

  // Released, the baked solid has nothing to spring back to.
  ASSERT_EQ(Send(s, absl::StrCat("remove_load { load_id: ", d.load_id(), " }")).code(), 0);
  Steps(s, 500);
  EXPECT_LT((s.core->solid().control_positions() - shape).cwiseAbs().maxCoeff(), 1e-6 * 3);

  // Undo (the bake; the drag's release is part of the drag's entry): the
  // rest shape before the bake, the solid where it is now.
  const Points now = s.core->solid().control_positions();
  const CommandReply u = Send(s, "undo {}");
  ASSERT_EQ(u.code(), 0) << u.message();
  EXPECT_THAT(u.history().what(), HasSubstr("bake"));
  EXPECT_EQ(s.core->solid().control_positions(), now);  // not rewound
  EXPECT_EQ(s.core->solid().discretization().control().positions(),
            Make().core->solid().discretization().control().positions());  // the old rest
  EXPECT_TRUE(s.core->solid().ActiveLoads().empty());  // the released drag stays released
  (void)before;
  (void)at_apply;
}

TEST(SculptCoreTest, ABakeIsReplayedFromItsJournalRecordToTheSameBits) {
  Session live = Make();
  std::vector<persist::JournalRecord> journal;
  auto send = [&](const std::string& text, bool build) {
    CommandRequest r;
    r.set_client_id("j");
    r.set_seq(++live.seq);
    ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(text, r.mutable_command()));
    std::shared_ptr<SimCore::Prebuilt> prebuilt;
    if (build) {
      live.core->Stamp(r);  // as the live loop does before building
      prebuilt = live.core->Prebuild(r)();
      Steps(live, 2);
    }
    persist::JournalRecord rec;
    rec.set_step(live.core->steps());
    rec.set_client_id("j");
    rec.set_seq(r.seq());
    *rec.mutable_command() = r.command();
    CommandReply reply;
    live.core->Process(r, &reply, prebuilt);
    ASSERT_EQ(reply.code(), 0) << reply.message();
    *rec.mutable_reply() = reply;
    journal.push_back(rec);
  };
  send(R"(drag { material_point { x: 1.5 y: 1.5 z: 3 } target { x: 1.0 y: 1.5 z: 3.4 }
          stiffness: 2e4 })", false);
  Steps(live, 150);
  send("edit { bake {} }", true);
  Steps(live, 40);
  send("edit { bake {} }", false);  // inline: the positions at its own step
  Steps(live, 20);
  const std::string want = live.core->solid().SaveState();
  EXPECT_EQ(ReplayedState(journal, live.core->steps()), want);
}

TEST(SculptCoreTest, ABakeIsRefusedWhileABoxPressureActsAndChangesNothing) {
  Session s = Make();
  ASSERT_EQ(Send(s, R"(add_pressure { region { box { min { x: -1 y: -1 z: 2.9 }
      max { x: 4 y: 4 z: 3.1 } } } pascals: 100 })").code(), 0);
  Steps(s, 10);
  const std::string before = s.core->solid().SaveState();
  const CommandReply r = Send(s, "edit { bake {} }");
  EXPECT_EQ(r.code(), static_cast<int>(absl::StatusCode::kFailedPrecondition));
  EXPECT_THAT(r.message(), HasSubstr("selects its faces by a box or sphere at rest"));
  EXPECT_EQ(s.core->solid().SaveState(), before);
}

TEST(SculptCoreTest, SnapshotsAndJournalReplayOfEditsAndUndosReachTheSameBits) {
  Session live = Make();
  std::vector<persist::JournalRecord> journal;
  auto send = [&](const std::string& text) {
    CommandRequest r;
    r.set_client_id("j");
    r.set_seq(++live.seq);
    ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(text, r.mutable_command()));
    persist::JournalRecord rec;
    rec.set_step(live.core->steps());
    rec.set_client_id("j");
    rec.set_seq(r.seq());
    *rec.mutable_command() = r.command();
    CommandReply reply;
    live.core->Process(r, &reply);
    *rec.mutable_reply() = reply;
    journal.push_back(rec);
  };
  Steps(live, 3);
  send("edit { extrude_faces { near { x: 1.5 y: 1.5 z: 3 } distance: 0.5 } }");
  Steps(live, 7);
  send(R"(drag { material_point { x: 1.5 y: 1.5 z: 3.5 } target { x: 1.5 y: 1.7 z: 3.8 }
          stiffness: 1e4 })");
  Steps(live, 5);
  // A snapshot here: an edited scene, a history across topology.
  persist::Snapshot snap;
  live.core->SaveTo(&snap);
  snap.set_solid_state(live.core->solid().SaveState());
  send("edit { delete_cells { near { x: 2.5 y: 2.5 z: 2.5 } } }");
  Steps(live, 4);
  send("undo {}");
  Steps(live, 4);
  send("undo {}");  // the drag
  send("edit { extrude_faces { faces: 9999 distance: 1 } }");  // refused, journaled
  Steps(live, 6);
  const std::string want = live.core->solid().SaveState();

  // Replay from the start.
  EXPECT_EQ(ReplayedState(journal, live.core->steps()), want);

  // Recover from the snapshot, then replay what followed it.
  Session recovered = Make();
  ASSERT_OK(recovered.core->RestoreFrom(snap));
  EXPECT_EQ(Cells(recovered), 28);
  EXPECT_EQ(recovered.core->history().undo_depth(), 2);
  for (const persist::JournalRecord& rec : journal) {
    if (rec.step() < snap.step() || (rec.step() == snap.step() && rec.seq() <= 2)) continue;
    ASSERT_OK(recovered.core->Replay(rec));
  }
  while (recovered.core->steps() < live.core->steps()) ASSERT_OK(recovered.core->StepOnce());
  EXPECT_EQ(recovered.core->solid().SaveState(), want);
  EXPECT_EQ(Cells(recovered), Cells(live));
}

// block4: the corotational model (rotation-invariant strain), backward
// Euler, gravity and penalty springs at the base. A twin without the edits
// is the reference: one step after each edit (the strain energy is the last
// step's), the edited solid's mechanical energy may differ from the twin's
// only by what the edit takes away or adds, not by a jump.
TEST(SculptCoreTest, AnEditAddsNoMoreEnergyThanItsNewMaterialCarries) {
  Session s = Make("block4"), twin = Make("block4");
  for (Session* x : {&s, &twin}) {
    const CommandReply r = Send(*x, R"(drag { material_point { x: 2 y: 2 z: 4 }
                                          target { x: 2.5 y: 2 z: 4.3 } stiffness: 2e4 })");
    ASSERT_EQ(r.code(), 0) << r.message();
    Steps(*x, 30);
    ASSERT_EQ(Send(*x, absl::StrCat("remove_load { load_id: ", r.load_id(), " }")).code(), 0);
    Steps(*x, 5);
  }
  auto total = [](const Session& x) {
    const solid::Energies e = x.core->solid().ComputeEnergies();
    return e.kinetic + e.strain + e.springs;
  };
  const double mass0 = s.core->solid().total_mass();
  ASSERT_GT(total(s), 0);
  ASSERT_EQ(Send(s, "edit { delete_cells { near { x: 3.5 y: 3.5 z: 3.5 } } }").code(), 0);
  Steps(s, 1);
  Steps(twin, 1);
  const double e1 = total(s), t1 = total(twin), mass1 = s.core->solid().total_mass();
  EXPECT_LT(mass1, mass0);
  ASSERT_EQ(Send(s, "edit { extrude_faces { near { x: 0.5 y: 0.5 z: 4 } distance: 0.3 } }").code(),
            0);
  Steps(s, 1);
  Steps(twin, 1);
  const double e2 = total(s), t2 = total(twin), mass2 = s.core->solid().total_mass();
  EXPECT_GT(mass2, mass1);
  std::cout << "energy (J) after a delete " << e1 << " (twin " << t1 << "); after an extrude "
            << e2 << " (twin " << t2 << "); mass " << mass0 << " -> " << mass1 << " -> " << mass2
            << " kg\n";
  // Deleting a corner cell takes its energy with it (and the neighbours'
  // subdivision rules change): within 1 % of the twin.
  EXPECT_LE(e1, 1.01 * t1);
  // Extruding adds a cell stress free in its rotated frame, moving with the
  // face it grew from: within 1 % of the twin.
  EXPECT_LE(e2, 1.01 * t2);
}

}  // namespace
}  // namespace dynsolid::server
