// What a session's core (SimCore) tells a viewer besides the surface: the
// active loads and constraints of every client and of the scene
// (InspectRequest.loads: SimCore::DescribeLoads, what the session loop
// answers Inspect with), through removal, undo, redo and a snapshot; and the
// mass field of its surface snapshots after a density paint.
#include <gmock/gmock.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "dynsolid/journal.pb.h"
#include "server/sim_core.h"
#include "server/solid_builder.h"
#include "tests/server/test_core.h"
#include "tests/testing/status_matchers.h"
#include "tests/testing/text_proto.h"

namespace dynsolid::server {
namespace {

using ::google::protobuf::util::MessageDifferencer;

using Core = TestCore;

Core Make(const std::string& builtin = "block3", int levels = 1) {
  return MakeTestCore(builtin, levels, /*start_paused=*/true);
}

CommandReply Send(Core& c, const std::string& client, const std::string& text) {
  const CommandReply reply = SendText(c, client, text);
  EXPECT_EQ(reply.code(), 0) << text << ": " << reply.message();
  return reply;
}

InspectReply Loads(const Core& c) {
  InspectReply r;
  c.core->DescribeLoads(&r);
  return r;
}

using ::dynsolid::testing::Parse;

Eigen::Vector3d E(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

const ActiveLoad* FindLoad(const InspectReply& r, int64_t id) {
  for (const ActiveLoad& l : r.loads()) {
    if (l.id() == id) return &l;
  }
  return nullptr;
}

std::vector<int64_t> LoadIds(const InspectReply& r) {
  std::vector<int64_t> ids;
  for (const ActiveLoad& l : r.loads()) ids.push_back(l.id());
  return ids;
}
std::vector<int64_t> ConstraintIds(const InspectReply& r) {
  std::vector<int64_t> ids;
  for (const ActiveConstraint& c : r.constraints()) ids.push_back(c.id());
  return ids;
}

constexpr char kPressureRegion[] = "sphere { center { x: 1.5 y: 1.5 z: 3 } radius: 0.8 }";
constexpr char kFixRegion[] =
    "box { min { x: 2.99 y: -0.01 z: -0.01 } max { x: 3.01 y: 3.01 z: 3.01 } }";

TEST(InspectCoreTest, LoadsAndConstraintsOfEveryClientWithIdsKindsPointsTargetsAndRegions) {
  Core c = Make();
  // The scene's own fixed bottom face: id 1, no client, 16 control points.
  InspectReply r = Loads(c);
  EXPECT_EQ(r.loads_size(), 0);
  ASSERT_EQ(r.constraints_size(), 1);
  EXPECT_EQ(r.constraints(0).id(), 1);
  EXPECT_EQ(r.constraints(0).client_id(), "");
  EXPECT_EQ(r.constraints(0).control_points(), 16);
  EXPECT_EQ(r.constraints(0).control_point_indices_size(), 16);
  EXPECT_DOUBLE_EQ(r.constraints(0).region().box().max().z(), 0.01);

  const int64_t force = Send(c, "alice",
                             "add_point_force { position { x: 1.5 y: 1.5 z: 2 } "
                             "force { x: 1 y: 2 z: -30 } }")
                            .load_id();
  const int64_t pressure =
      Send(c, "bob", absl::StrCat("add_pressure { region { ", kPressureRegion, " } pascals: 500 }"))
          .load_id();
  const int64_t drag = Send(c, "alice",
                            "drag { material_point { x: 2.5 y: 1.5 z: 3 } "
                            "target { x: 2.7 y: 1.5 z: 3.2 } stiffness: 2e3 }")
                           .load_id();
  Send(c, "alice",
       absl::StrCat("move_drag { load_id: ", drag, " target { x: 2.9 y: 1.4 z: 3.4 } }"));
  const int64_t curve = Send(c, "carol",
                             "curve { material_points { x: 0.5 y: 0.5 z: 3 } "
                             "material_points { x: 2.5 y: 0.5 z: 3 } "
                             "targets { x: 0.5 y: 0.5 z: 3.2 } targets { x: 2.5 y: 0.5 z: 3.2 } "
                             "stiffness: 1e3 samples: 5 }")
                            .load_id();
  Send(c, "carol",
       absl::StrCat("move_drag { load_id: ", curve,
                    " targets { x: 0.5 y: 0.4 z: 3.3 } targets { x: 2.5 y: 0.6 z: 3.5 } }"));
  const int64_t fix =
      Send(c, "bob", absl::StrCat("fix_region { ", kFixRegion, " }")).constraint_id();
  Send(c, "dave", "set_gravity { z: -9.81 }");
  EXPECT_THAT(std::vector<int64_t>({force, pressure, drag, curve, fix}),
              ::testing::ElementsAre(2, 3, 4, 5, 6));
  Steps(c, 30);

  r = Loads(c);
  EXPECT_THAT(LoadIds(r), ::testing::ElementsAre(force, pressure, drag, curve));
  EXPECT_THAT(ConstraintIds(r), ::testing::ElementsAre(1, fix));
  EXPECT_EQ(E(r.gravity()), Eigen::Vector3d(0, 0, -9.81));
  const solid::Solid& solid = c.core->solid();

  const ActiveLoad& f = *FindLoad(r, force);
  EXPECT_EQ(f.kind(), "point_force");
  EXPECT_EQ(f.client_id(), "alice");
  EXPECT_EQ(E(f.material_point()), Eigen::Vector3d(1.5, 1.5, 2));
  EXPECT_EQ(E(f.force()), Eigen::Vector3d(1, 2, -30));
  absl::StatusOr<std::vector<Eigen::Vector3d>> now =
      solid.MaterialPositions({E(f.material_point())});
  ASSERT_OK(now);
  EXPECT_LT((E(f.position()) - (*now)[0]).norm(), 1e-12) << "the point where it is now";
  EXPECT_GT((E(f.position()) - E(f.material_point())).norm(), 1e-6) << "the solid moved";
  EXPECT_EQ(f.material_points_size() + f.positions_size() + f.targets_size(), 0);

  const ActiveLoad& p = *FindLoad(r, pressure);
  EXPECT_EQ(p.kind(), "pressure");
  EXPECT_EQ(p.client_id(), "bob");
  EXPECT_EQ(p.pressure(), 500);
  EXPECT_TRUE(MessageDifferencer::Equals(p.region(), Parse<Region>(kPressureRegion)));
  ASSERT_GT(p.surface_quads_size(), 0);
  EXPECT_TRUE(std::is_sorted(p.surface_quads().begin(), p.surface_quads().end()));
  EXPECT_LT(p.surface_quads_size(), static_cast<int>(solid.BoundarySurface().quads.size()));
  EXPECT_FALSE(p.has_material_point());

  const ActiveLoad& d = *FindLoad(r, drag);
  EXPECT_EQ(d.kind(), "drag");
  EXPECT_EQ(d.client_id(), "alice");
  EXPECT_EQ(E(d.material_point()), Eigen::Vector3d(2.5, 1.5, 3));
  EXPECT_EQ(E(d.target()), Eigen::Vector3d(2.9, 1.4, 3.4)) << "the latest target";
  EXPECT_EQ(d.stiffness(), 2e3);
  now = solid.MaterialPositions({E(d.material_point())});
  ASSERT_OK(now);
  EXPECT_LT((E(d.position()) - (*now)[0]).norm(), 1e-12);
  EXPECT_GT((E(d.position()) - E(d.material_point())).norm(), 1e-6) << "the solid moved";

  const ActiveLoad& cv = *FindLoad(r, curve);
  EXPECT_EQ(cv.kind(), "curve");
  EXPECT_EQ(cv.client_id(), "carol");
  EXPECT_EQ(cv.stiffness(), 1e3);
  ASSERT_EQ(cv.material_points_size(), 5);
  ASSERT_EQ(cv.positions_size(), 5);
  ASSERT_EQ(cv.targets_size(), 5);
  for (int k = 0; k < 5; ++k) {
    // Evenly spaced along the straight polyline, and its target polyline.
    EXPECT_LT((E(cv.material_points(k)) - Eigen::Vector3d(0.5 + 0.5 * k, 0.5, 3)).norm(), 1e-12)
        << k;
    const Eigen::Vector3d target =
        Eigen::Vector3d(0.5, 0.4, 3.3) + (k / 4.0) * Eigen::Vector3d(2, 0.2, 0.2);
    EXPECT_LT((E(cv.targets(k)) - target).norm(), 1e-12) << k;
    now = solid.MaterialPositions({E(cv.material_points(k))});
    ASSERT_OK(now);
    EXPECT_LT((E(cv.positions(k)) - (*now)[0]).norm(), 1e-12) << k;
  }
  EXPECT_FALSE(cv.has_material_point());
  EXPECT_EQ(cv.curve().material_points_size(), 2);
  EXPECT_EQ(E(cv.curve().targets(1)), Eigen::Vector3d(2.5, 0.6, 3.5)) << "the latest polyline";
  EXPECT_EQ(cv.curve().samples(), 5);

  const ActiveConstraint& x = r.constraints(1);
  EXPECT_EQ(x.client_id(), "bob");
  EXPECT_TRUE(MessageDifferencer::Equals(x.region(), Parse<Region>(kFixRegion)));
  EXPECT_EQ(x.control_points(), 16);  // the x = 3 face of the 4 x 4 x 4 control points
  ASSERT_EQ(x.control_point_indices_size(), 16);
  for (int32_t i : x.control_point_indices()) {
    EXPECT_NEAR(solid.discretization().control().positions()(i, 0), 3.0, 1e-9)
        << "control point " << i;
  }

  // Removed: gone. (At one step: undo then restores this very state.)
  Send(c, "erin", absl::StrCat("remove_load { load_id: ", force, " }"));
  Send(c, "erin", absl::StrCat("remove_load { load_id: ", drag, " }"));
  Send(c, "erin", absl::StrCat("unfix { constraint_id: ", fix, " }"));
  const InspectReply removed = Loads(c);
  EXPECT_THAT(LoadIds(removed), ::testing::ElementsAre(pressure, curve));
  EXPECT_THAT(ConstraintIds(removed), ::testing::ElementsAre(1));
  Send(c, "erin", absl::StrCat("remove_load { load_id: ", pressure, " }"));
  Send(c, "erin", absl::StrCat("remove_load { load_id: ", curve, " }"));
  const InspectReply none = Loads(c);
  EXPECT_EQ(none.loads_size(), 0);
  EXPECT_THAT(ConstraintIds(none), ::testing::ElementsAre(1));
  // Undone (erin's own removals: the force, the pin, the pressure): back as
  // they were (points, regions), owners included, under new ids; the drag
  // and the curve stay released (their release belongs to their drags).
  auto same = [](const InspectReply& x, const InspectReply& y) {
    InspectReply a = x, b = y;
    for (InspectReply* r : {&a, &b}) {
      for (ActiveLoad& l : *r->mutable_loads()) l.set_id(0);
      std::sort(r->mutable_loads()->begin(), r->mutable_loads()->end(),
                [](const ActiveLoad& p, const ActiveLoad& q) { return p.kind() < q.kind(); });
      for (ActiveConstraint& k : *r->mutable_constraints()) k.set_id(0);
      r->clear_surface_positions();
    }
    return MessageDifferencer::Equals(a, b);
  };
  InspectReply back = r;
  back.clear_loads();
  for (const ActiveLoad& l : r.loads()) {
    if (l.kind() != "drag" && l.kind() != "curve") *back.add_loads() = l;
  }
  for (int i = 0; i < 3; ++i) EXPECT_EQ(Send(c, "erin", "undo {}").code(), 0);
  const InspectReply undone = Loads(c);
  EXPECT_TRUE(same(undone, back)) << "want:\n" << back.DebugString() << "after undo:\n"
                                  << undone.DebugString();
  EXPECT_EQ(c.core->history().undo_depth("erin"), 0) << "erin has nothing more to undo";
  // Redone: gone again; undone: back again.
  for (int i = 0; i < 3; ++i) EXPECT_EQ(Send(c, "erin", "redo {}").code(), 0);
  EXPECT_TRUE(same(Loads(c), none));
  for (int i = 0; i < 3; ++i) EXPECT_EQ(Send(c, "erin", "undo {}").code(), 0);
  EXPECT_TRUE(same(Loads(c), back));

  // A snapshot keeps who added what.
  persist::Snapshot snap;
  c.core->SaveTo(&snap);
  snap.set_solid_state(c.core->solid().SaveState());
  Core recovered = Make();
  ASSERT_OK(recovered.core->RestoreFrom(snap));
  EXPECT_TRUE(MessageDifferencer::Equals(Loads(recovered), Loads(c)));
}

TEST(InspectCoreTest, AnUndoneIdGivenAgainBelongsToItsNewOwner) {
  Core c = Make();
  const std::string add = "add_point_force { position { x: 1.5 y: 1.5 z: 2 } force { z: -1 } }";
  const int64_t first = Send(c, "alice", add).load_id();
  Send(c, "alice", "undo {}");
  const int64_t again = Send(c, "bob", add).load_id();
  EXPECT_NE(again, first);  // an undo removes the load; ids go on
  const InspectReply r = Loads(c);
  ASSERT_EQ(r.loads_size(), 1);
  EXPECT_EQ(r.loads(0).client_id(), "bob");
  // A refused command and a resend change no owner.
  CommandRequest resend;
  resend.set_client_id("alice");
  resend.set_seq(1);
  ASSERT_TRUE(google::protobuf::TextFormat::ParseFromString(add, resend.mutable_command()));
  CommandReply reply;
  EXPECT_EQ(c.core->Process(resend, &reply), SimCore::Outcome::kDuplicate);
  CommandRequest bad = resend;
  bad.set_seq(10);
  bad.mutable_command()->mutable_add_point_force()->mutable_position()->set_z(50);
  EXPECT_EQ(c.core->Process(bad, &reply), SimCore::Outcome::kRejected);
  EXPECT_EQ(c.core->owner(again), "bob");
  EXPECT_EQ(c.core->owner(1), "") << "the scene's fixed region";
}

TEST(InspectCoreTest, ScenePointForcesAndPressuresAreListedFirstWithoutAClient) {
  CreateSessionRequest create;
  create.set_scene_text(R"pb(
    name: "loaded"
    mesh { block { nx: 2 ny: 1 nz: 1 } }
    subdivision { levels: 1 }
    materials { base { young_modulus: 1e5 density: 1000 } }
    loads {
      point_forces {
        position { x: 1.5 y: 0.5 z: 0.5 }
        force { z: -10 }
      }
      pressures {
        region {
          box {
            min { x: -1 y: -1 z: 0.9 }
            max { x: 3 y: 2 z: 2 }
          }
        }
        pascals: -50
      }
    }
    constraints {
      fixed {
        box {
          min { x: -0.01 y: -1 z: -1 }
          max { x: 0.01 y: 2 z: 2 }
        }
      }
    }
  )pb");
  absl::StatusOr<SceneRequest> request = ResolveSceneRequest(create);
  ASSERT_OK(request);
  BuildLimits limits;
  limits.sim_threads = 1;
  SolidFactory factory = MakeSolidFactory(*request, limits);
  absl::StatusOr<std::shared_ptr<solid::Solid>> solid = factory(nullptr);
  ASSERT_OK(solid);
  SimCore core(*solid, CoreOptions(), true, request->scene, factory);
  InspectReply r;
  core.DescribeLoads(&r);
  ASSERT_EQ(r.loads_size(), 2);
  EXPECT_EQ(r.loads(0).id(), 1);
  EXPECT_EQ(r.loads(0).kind(), "point_force");
  EXPECT_EQ(E(r.loads(0).force()), Eigen::Vector3d(0, 0, -10));
  EXPECT_EQ(r.loads(1).id(), 2);
  EXPECT_EQ(r.loads(1).kind(), "pressure");
  EXPECT_EQ(r.loads(1).pressure(), -50);
  ASSERT_EQ(r.constraints_size(), 1);
  EXPECT_EQ(r.constraints(0).id(), 3);
  for (const ActiveLoad& l : r.loads()) EXPECT_EQ(l.client_id(), "");
  // At rest a material point is where it is.
  EXPECT_LT((E(r.loads(0).position()) - Eigen::Vector3d(1.5, 0.5, 0.5)).norm(), 1e-9);
}

TEST(InspectCoreTest, ADensityPaintBumpsTheFieldsVersionAndRaisesTheMassField) {
  Core c = Make();
  std::shared_ptr<const SurfaceSnapshot> before = c.core->MakeSnapshot(true);
  const size_t n = static_cast<size_t>(before->topology->vertex_count);
  ASSERT_EQ(before->mass.size(), n);
  for (float m : before->mass) EXPECT_FLOAT_EQ(m, 1000.0f) << "block3's density";
  const int64_t version = c.core->fields_version();
  Send(c, "painter",
       "paint_material { region { sphere { center { x: 3 y: 3 z: 3 } radius: 1.2 } } "
       "material { density: 4000 } strength: 1 }");
  EXPECT_EQ(c.core->fields_version(), version + 1) << "as a stiffness paint does";
  std::shared_ptr<const SurfaceSnapshot> after = c.core->MakeSnapshot(true);
  EXPECT_EQ(after->fields_version, version + 1);
  ASSERT_EQ(after->mass.size(), n);
  int raised = 0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d x(after->positions[3 * i], after->positions[3 * i + 1],
                            after->positions[3 * i + 2]);
    const double r = (x - Eigen::Vector3d(3, 3, 3)).norm();
    if (r < 0.3) {
      EXPECT_GT(after->mass[i], 2000.0f) << "vertex " << i << " near the corner";
      ++raised;
    }
    // Cells of 0.5 m at level 1: a vertex's cells reach 0.87 m.
    if (r > 1.2 + 0.5 * std::sqrt(3.0)) {
      EXPECT_FLOAT_EQ(after->mass[i], 1000.0f) << "vertex " << i;
    }
    EXPECT_EQ(after->stiffness[i], before->stiffness[i]) << "only the density was painted";
  }
  EXPECT_GT(raised, 0);
  // Undoing the paint puts the field back and moves the version on again.
  Send(c, "painter", "undo {}");
  EXPECT_EQ(c.core->fields_version(), version + 2);
  EXPECT_EQ(c.core->MakeSnapshot(true)->mass, before->mass);
}

}  // namespace
}  // namespace dynsolid::server
