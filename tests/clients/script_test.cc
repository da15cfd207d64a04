// The client's script language: every verb parses into the right
// service.proto Command (or client action), and every kind of mistake is
// reported with file:line, the verb and the bad token, exactly.
#include "clients/lib/script.h"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace dynsolid::client {
namespace {

using ::testing::HasSubstr;

Script Parse(const std::string& text) {
  absl::StatusOr<Script> s = ParseScript(text, "s.txt");
  EXPECT_TRUE(s.ok()) << s.status().message();
  return s.ok() ? *s : Script();
}

// The whole error message of a script that must fail.
std::string Error(const std::string& text) {
  absl::StatusOr<Script> s = ParseScript(text, "s.txt");
  EXPECT_FALSE(s.ok()) << "parsed: " << text;
  if (s.ok()) return "";
  EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
  return std::string(s.status().message());
}

TEST(ScriptTest, EveryVerbBuildsItsCommand) {
  const Script s = Parse(
      "# a comment line\n"
      "\n"
      "force at=1.5,1.5,3 f=0,0,2e4 name=pull   # trailing comment\n"
      "pressure sphere=1.5,1.5,3,1.2 pa=-500 name=puff\n"
      "gravity 0,0,-9.81\n"
      "gravity g=0,0,0\n"
      "remove pull\n"
      "remove load=7\n"
      "fix box=0,0,0,3,3,0.1 cells=0,4 name=pin\n"
      "unfix pin\n"
      "unfix constraint=3\n"
      "paint sphere=1,1,1,0.5 E=3e5 nu=0.45 density=1200 damping=10 strength=0.5\n"
      "paint cells=2 E=1e6\n"
      "pause\n"
      "resume\n"
      "step 100\n"
      "step count=5\n"
      "save\n"
      "wait 20\n"
      "wait\n"
      "wait_until step=500\n"
      "sleep 0.25\n"
      "snapshot pulled\n"
      "snapshot\n");
  ASSERT_EQ(s.lines.size(), 22u);
  const auto& l = s.lines;
  EXPECT_EQ(l[0].line, 3);
  EXPECT_EQ(l[0].name, "pull");
  ASSERT_TRUE(l[0].command.has_add_point_force());
  EXPECT_EQ(l[0].command.add_point_force().position().x(), 1.5);
  EXPECT_EQ(l[0].command.add_point_force().position().z(), 3);
  EXPECT_EQ(l[0].command.add_point_force().force().z(), 2e4);

  ASSERT_TRUE(l[1].command.has_add_pressure());
  EXPECT_EQ(l[1].command.add_pressure().pascals(), -500);
  EXPECT_EQ(l[1].command.add_pressure().region().sphere().radius(), 1.2);
  EXPECT_EQ(l[1].command.add_pressure().region().sphere().center().y(), 1.5);

  ASSERT_TRUE(l[2].command.has_set_gravity());
  EXPECT_EQ(l[2].command.set_gravity().z(), -9.81);
  ASSERT_TRUE(l[3].command.has_set_gravity());
  EXPECT_EQ(l[3].command.set_gravity().z(), 0);

  ASSERT_TRUE(l[4].command.has_remove_load());
  EXPECT_EQ(l[4].ref, "pull");
  ASSERT_TRUE(l[5].command.has_remove_load());
  EXPECT_EQ(l[5].ref, "");
  EXPECT_EQ(l[5].command.remove_load().load_id(), 7);

  ASSERT_TRUE(l[6].command.has_fix_region());
  EXPECT_EQ(l[6].command.fix_region().box().max().z(), 0.1);
  EXPECT_EQ(l[6].command.fix_region().box().min().x(), 0);
  EXPECT_THAT(l[6].command.fix_region().control_cells(), ::testing::ElementsAre(0, 4));
  EXPECT_EQ(l[6].name, "pin");
  ASSERT_TRUE(l[7].command.has_unfix());
  EXPECT_EQ(l[7].ref, "pin");
  EXPECT_EQ(l[8].command.unfix().constraint_id(), 3);

  ASSERT_TRUE(l[9].command.has_paint_material());
  const MaterialPaint& p = l[9].command.paint_material();
  EXPECT_EQ(p.material().young_modulus(), 3e5);
  EXPECT_EQ(p.material().poisson_ratio(), 0.45);
  EXPECT_EQ(p.material().density(), 1200);
  EXPECT_EQ(p.material().damping(), 10);
  EXPECT_EQ(p.strength(), 0.5);
  EXPECT_EQ(l[10].command.paint_material().strength(), 1) << "strength defaults to 1";
  EXPECT_THAT(l[10].command.paint_material().region().control_cells(), ::testing::ElementsAre(2));
  EXPECT_FALSE(l[10].command.paint_material().region().has_sphere());

  EXPECT_TRUE(l[11].command.has_pause());
  EXPECT_TRUE(l[12].command.has_resume());
  EXPECT_EQ(l[13].command.step().count(), 100);
  EXPECT_EQ(l[14].command.step().count(), 5);
  EXPECT_TRUE(l[15].command.has_save());

  EXPECT_EQ(l[16].kind, ScriptLine::Kind::kWait);
  EXPECT_EQ(l[16].steps, 20);
  EXPECT_EQ(l[17].kind, ScriptLine::Kind::kWaitSteps);
  EXPECT_EQ(l[18].kind, ScriptLine::Kind::kWaitUntil);
  EXPECT_EQ(l[18].steps, 500);
  EXPECT_EQ(l[19].kind, ScriptLine::Kind::kSleep);
  EXPECT_EQ(l[19].seconds, 0.25);
  EXPECT_EQ(l[20].kind, ScriptLine::Kind::kSnapshot);
  EXPECT_EQ(l[20].name, "pulled");
  EXPECT_EQ(l[21].name, "snapshot_line24");
  EXPECT_EQ(s.Where(l[21]), "s.txt:24");

  // Every command kind of service.proto is reachable from the language.
  std::set<std::string> kinds;
  const Script sculpt = Parse(
      "drag at=1,1,2 to=1,1,3 name=g\nmove g to=1,1,2\ncurve along=0,0,0/1,1,1 to=0,0,0/1,1,2\n"
      "extrude near=1,1,3 d=1\nundo\nredo\nrevert\n");
  for (const Script* script : {&s, &sculpt}) {
    for (const ScriptLine& line : script->lines) {
      if (line.kind == ScriptLine::Kind::kCommand) kinds.insert(CommandKindName(line.command));
    }
  }
  // (The kinds are the oneof's fields; gesture is a mark on any of them.)
  const google::protobuf::OneofDescriptor* kind = Command::descriptor()->FindOneofByName("kind");
  ASSERT_NE(kind, nullptr);
  for (int i = 0; i < kind->field_count(); ++i) {
    EXPECT_EQ(kinds.count(kind->field(i)->name()), 1u)
        << kind->field(i)->name() << " has no script verb";
  }
}

TEST(ScriptTest, BakeAndClayPaint) {
  const Script s = Parse(
      "bake\npaint sphere=0,0,0,1 preset=clay\npaint cells=3 yield=0.02 flow=20 hardening=0.1\n");
  ASSERT_EQ(s.lines.size(), 3u);
  EXPECT_TRUE(s.lines[0].command.edit().has_bake());
  EXPECT_EQ(s.lines[0].command.edit().bake().rest_positions_size(), 0);
  EXPECT_EQ(s.lines[1].command.paint_material().material().preset(), Material::CLAY);
  const Material& m = s.lines[2].command.paint_material().material();
  EXPECT_EQ(m.yield_strain(), 0.02);
  EXPECT_EQ(m.flow_rate(), 20);
  EXPECT_EQ(m.hardening(), 0.1);
  EXPECT_EQ(Error("paint cells=1 preset=stone\n"),
            "s.txt:1: paint: \"preset=stone\" is not a preset: rubber, clay or wax");
  EXPECT_EQ(Error("paint cells=1 yield=2\n"), "s.txt:1: paint: \"yield=2\" must be in [0, 1)");
}

TEST(ScriptTest, ErrorsNameFileLineVerbAndToken) {
  EXPECT_EQ(Error("forse at=1,2,3 f=0,0,1\n"),
            "s.txt:1: unknown command \"forse\" (commands: force, pressure, gravity, remove, fix, "
            "unfix, paint, drag, curve, move, release, delete, extrude, merge, subdivide, sharp, "
            "smooth, bake, undo, redo, revert, pause, resume, step, save, wait, wait_until, sleep, "
            "snapshot)");
  EXPECT_EQ(Error("\n\nforce at=1,2 f=0,0,1\n"),
            "s.txt:3: force: \"at=1,2\" needs 3 numbers, got 2");
  EXPECT_EQ(Error("force at=1,2,3x f=0,0,1\n"),
            "s.txt:1: force: bad number \"3x\" in \"at=1,2,3x\"");
  EXPECT_EQ(Error("force at=1,,3 f=0,0,1\n"), "s.txt:1: force: bad number \"\" in \"at=1,,3\"");
  EXPECT_EQ(Error("force at=1,2,3 f=0,nan,1\n"),
            "s.txt:1: force: \"nan\" in \"f=0,nan,1\" is not a finite number");
  EXPECT_EQ(Error("force at=1,2,3 f=inf,0,1\n"),
            "s.txt:1: force: \"inf\" in \"f=inf,0,1\" is not a finite number");
  EXPECT_EQ(Error("force at=1,2,3\n"), "s.txt:1: force: missing f=FX,FY,FZ");
  EXPECT_EQ(Error("force f=1,2,3\n"), "s.txt:1: force: missing at=X,Y,Z");
  EXPECT_EQ(Error("force at=1,2,3 f=0,0,1 foo=2\n"),
            "s.txt:1: force: unknown key \"foo\" in \"foo=2\" (keys: at, f, name)");
  EXPECT_EQ(Error("force at=1,2,3 at=1,2,3 f=0,0,1\n"),
            "s.txt:1: force: at given twice (\"at=1,2,3\")");
  EXPECT_EQ(Error("force 1,2,3\n"),
            "s.txt:1: force: unexpected argument \"1,2,3\" (keys: at, f, name)");
  EXPECT_EQ(Error("pause now\n"), "s.txt:1: pause: unexpected argument \"now\" (takes none)");
  EXPECT_EQ(Error("save x=1\n"),
            "s.txt:1: save: unknown key \"x\" in \"x=1\" (takes no arguments)");
  EXPECT_EQ(Error("step 10 20\n"), "s.txt:1: step: unexpected second value \"20\"");
  EXPECT_EQ(Error("step 0\n"), "s.txt:1: step: \"0\" must be an integer in [1, 1000000]");
  EXPECT_EQ(Error("step count=2.5\n"),
            "s.txt:1: step: \"count=2.5\" must be an integer in [1, 1000000]");
  EXPECT_EQ(Error("step\n"), "s.txt:1: step: missing count=N");
  EXPECT_EQ(Error("wait -1\n"), "s.txt:1: wait: \"-1\" must be an integer in [0, 1125899906842624]");
  EXPECT_EQ(Error("sleep -0.5\n"), "s.txt:1: sleep: \"-0.5\" must be in [0, 3600] seconds");
  EXPECT_EQ(Error("sleep soon\n"), "s.txt:1: sleep: bad number \"soon\" in \"soon\"");
  EXPECT_EQ(Error("pressure pa=100\n"),
            "s.txt:1: pressure: needs a region: box=X0,Y0,Z0,X1,Y1,Z1, sphere=X,Y,Z,R and/or "
            "cells=I,J,...");
  EXPECT_EQ(Error("pressure sphere=0,0,0,1\n"), "s.txt:1: pressure: missing pa=PASCALS");
  EXPECT_EQ(Error("pressure sphere=0,0,0,1 pa=0\n"),
            "s.txt:1: pressure: \"pa=0\": pascals must be non-zero");
  EXPECT_EQ(Error("pressure sphere=0,0,0,-1 pa=5\n"),
            "s.txt:1: pressure: \"sphere=0,0,0,-1\": the radius must be > 0, got -1");
  EXPECT_EQ(Error("fix box=0,0,0,1,1\n"),
            "s.txt:1: fix: \"box=0,0,0,1,1\" needs 6 numbers, got 5");
  EXPECT_EQ(Error("fix box=0,2,0,1,1,1\n"),
            "s.txt:1: fix: \"box=0,2,0,1,1,1\": min exceeds max on y (2 > 1)");
  EXPECT_EQ(Error("fix box=0,0,0,1,1,1 sphere=0,0,0,1\n"),
            "s.txt:1: fix: \"box=0,0,0,1,1,1\" and \"sphere=0,0,0,1\": a region has one shape "
            "(box or sphere)");
  EXPECT_EQ(Error("fix cells=1,-2\n"),
            "s.txt:1: fix: bad cell index \"-2\" in \"cells=1,-2\" (integers >= 0)");
  EXPECT_EQ(Error("paint sphere=0,0,0,1\n"),
            "s.txt:1: paint: needs at least one of E=PASCALS, nu=RATIO, density=KG_M3, "
            "damping=KG_M3_S, preset=rubber|clay|wax, yield=STRAIN, flow=PER_SECOND, "
            "hardening=RATIO");
  EXPECT_EQ(Error("paint sphere=0,0,0,1 nu=0.5\n"),
            "s.txt:1: paint: \"nu=0.5\" must be in [0, 0.5)");
  EXPECT_EQ(Error("paint sphere=0,0,0,1 E=-3\n"), "s.txt:1: paint: \"E=-3\" must be >= 0");
  EXPECT_EQ(Error("paint sphere=0,0,0,1 E=3 strength=0\n"),
            "s.txt:1: paint: \"strength=0\" must be in (0, 1]");
  EXPECT_EQ(Error("gravity 0,0\n"), "s.txt:1: gravity: \"0,0\" needs 3 numbers, got 2");
  EXPECT_EQ(Error("snapshot a/b\n"),
            "s.txt:1: snapshot: bad name \"a/b\" (a letter or _, then letters, digits, _ - .; at "
            "most 64)");
}

TEST(ScriptTest, NamesAreCheckedAcrossLines) {
  EXPECT_EQ(Error("remove pull\n"),
            "s.txt:1: remove: unknown load \"pull\" in \"pull\" (no earlier force or pressure has "
            "name=pull)");
  EXPECT_EQ(Error("fix sphere=0,0,0,1 name=pin\nremove load=pin\n"),
            "s.txt:2: remove: \"load=pin\" names a constraint (line 1), not a load");
  EXPECT_EQ(Error("force at=0,0,0 f=1,0,0 name=p\nunfix p\n"),
            "s.txt:2: unfix: \"p\" names a load (line 1), not a constraint");
  EXPECT_EQ(Error("force at=0,0,0 f=1,0,0 name=p\nfix sphere=0,0,0,1 name=p\n"),
            "s.txt:2: fix: name \"p\" already used at line 1");
  EXPECT_EQ(Error("force at=0,0,0 f=1,0,0 name=9p\n"),
            "s.txt:1: force: bad name in \"name=9p\" (a letter or _, then letters, digits, _ - .; "
            "at most 64)");
  EXPECT_EQ(Error("remove 0\n"), "s.txt:1: remove: \"0\": an id is >= 1");
  // A name is usable only after the line that binds it.
  EXPECT_THAT(Error("remove late\nforce at=0,0,0 f=1,0,0 name=late\n"),
              HasSubstr("s.txt:1: remove: unknown load \"late\""));
}

TEST(ScriptTest, EveryBadLineIsReportedAndGoodLinesDoNotHideThem) {
  const std::string e = Error("step 5\nstep x\npause\nfoo\nwait 3\nsleep\n");
  EXPECT_EQ(e,
            "s.txt:2: step: \"x\" must be an integer in [1, 1000000]\n"
            "s.txt:4: unknown command \"foo\" (commands: force, pressure, gravity, remove, fix, "
            "unfix, paint, drag, curve, move, release, delete, extrude, merge, subdivide, sharp, "
            "smooth, bake, undo, redo, revert, pause, resume, step, save, wait, wait_until, sleep, snapshot)\n"
            "s.txt:6: sleep: missing seconds=SECONDS");
  EXPECT_EQ(Error("wait_until\n"), "s.txt:1: wait_until: missing step=N");
  // At most 20 are listed.
  std::string many;
  for (int i = 0; i < 30; ++i) many += "bad\n";
  const std::string m = Error(many);
  EXPECT_THAT(m, HasSubstr("s.txt:20: unknown command"));
  EXPECT_THAT(m, ::testing::Not(HasSubstr("s.txt:21:")));
  EXPECT_THAT(m, ::testing::EndsWith("s.txt: more errors not shown"));
}

TEST(ScriptTest, EmptyAndCommentOnlyScriptsParseToNothing) {
  EXPECT_TRUE(Parse("").lines.empty());
  EXPECT_TRUE(Parse("# nothing\n   \t\n# more\n").lines.empty());
  // CRLF line ends are fine.
  const Script s = Parse("step 3\r\npause\r\n");
  ASSERT_EQ(s.lines.size(), 2u);
  EXPECT_EQ(s.lines[0].command.step().count(), 3);
}

}  // namespace
}  // namespace dynsolid::client

namespace dynsolid::client {
namespace {

TEST(ScriptTest, SculptingVerbsBuildTheirCommands) {
  const Script s = Parse(
      "drag at=1,1,2 to=1.5,1,2.5 k=5e3 name=grab\n"
      "move grab to=2,1,2.5\n"
      "release grab\n"
      "curve along=0,1,2/3,1,2 to=0,1,2/3,1,2.5 samples=8 name=bend\n"
      "move bend to=0,1,2/3,1,3\n"
      "extrude near=1.5,1.5,3 d=0.5 layers=2\n"
      "extrude faces=3,4 d=0.25\n"
      "delete cells=0\n"
      "delete near=0.5,0.5,0.5/2.5,2.5,2.5\n"
      "subdivide cells=13\n"
      "merge near=0,1,1/3,1,1\n"
      "merge faces=1,7\n"
      "sharp edges=0-1,1-5\n"
      "smooth edges=0-1\n"
      "paint sphere=1,1,1,0.5 density=3000 falloff=0.5\n"
      "undo\n"
      "redo\n");
  ASSERT_EQ(s.lines.size(), 17u);
  const auto& l = s.lines;
  EXPECT_EQ(l[0].command.drag().stiffness(), 5e3);
  EXPECT_EQ(l[0].command.drag().target().z(), 2.5);
  EXPECT_EQ(l[0].name, "grab");
  EXPECT_EQ(l[1].ref, "grab");
  EXPECT_EQ(l[1].command.move_drag().target().x(), 2);
  EXPECT_EQ(l[2].ref, "grab");
  EXPECT_TRUE(l[2].command.has_remove_load());
  EXPECT_EQ(l[3].command.curve().material_points_size(), 2);
  EXPECT_EQ(l[3].command.curve().targets(1).z(), 2.5);
  EXPECT_EQ(l[3].command.curve().samples(), 8);
  EXPECT_EQ(l[4].command.move_drag().targets_size(), 2);
  const ExtrudeFaces& x = l[5].command.edit().extrude_faces();
  EXPECT_EQ(x.near_size(), 1);
  EXPECT_EQ(x.distance(), 0.5);
  EXPECT_EQ(x.layers(), 2);
  EXPECT_THAT(l[6].command.edit().extrude_faces().faces(), ::testing::ElementsAre(3, 4));
  EXPECT_EQ(l[6].command.edit().extrude_faces().layers(), 1);
  EXPECT_THAT(l[7].command.edit().delete_cells().cells(), ::testing::ElementsAre(0));
  EXPECT_EQ(l[8].command.edit().delete_cells().near_size(), 2);
  EXPECT_THAT(l[9].command.edit().subdivide_cells().cells(), ::testing::ElementsAre(13));
  EXPECT_EQ(l[10].command.edit().merge_faces().near_size(), 2);
  EXPECT_EQ(l[11].command.edit().merge_faces().face_b(), 7);
  EXPECT_EQ(l[12].command.edit().sharp_edges().edges_size(), 2);
  EXPECT_TRUE(l[12].command.edit().sharp_edges().sharp());
  EXPECT_FALSE(l[13].command.edit().sharp_edges().sharp());
  EXPECT_EQ(l[14].command.paint_material().falloff(), 0.5);
  EXPECT_TRUE(l[15].command.has_undo());
  EXPECT_TRUE(l[16].command.has_redo());
}

TEST(ScriptTest, SculptingMistakesAreNamed) {
  EXPECT_THAT(Error("extrude d=0.5\n"), HasSubstr("s.txt:1: extrude: needs faces=I,J,... or near="));
  EXPECT_THAT(Error("extrude faces=1 d=-1\n"), HasSubstr("\"d=-1\" must be > 0 metres"));
  EXPECT_THAT(Error("merge faces=1\n"), HasSubstr("needs two faces, got 1"));
  EXPECT_THAT(Error("sharp edges=1-x\n"), HasSubstr("bad edge \"1-x\""));
  EXPECT_THAT(Error("curve along=0,0,0/1,1,1 to=0,0,0\n"), HasSubstr("needs at least 2 points"));
  EXPECT_THAT(Error("drag at=1,1,1 to=2,2,2 k=0\n"), HasSubstr("\"k=0\" must be > 0 N/m"));
  EXPECT_THAT(Error("move nothing to=1,1,1\n"), HasSubstr("unknown load \"nothing\""));
  EXPECT_THAT(Error("delete cells=-1\n"), HasSubstr("bad index \"-1\""));
  EXPECT_THAT(Error("paint sphere=1,1,1,1 E=1 falloff=2\n"), HasSubstr("\"falloff=2\" must be in [0, 1]"));
}

}  // namespace
}  // namespace dynsolid::client
