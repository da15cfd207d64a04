#include "clients/lib/script.h"

#include <cmath>
#include <map>
#include <optional>
#include <set>

#include "absl/status/status.h"
#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"

namespace dynsolid::client {
namespace {

constexpr int kMaxErrors = 20;
constexpr int64_t kMaxStepCount = 1'000'000;
constexpr double kMaxSleepSeconds = 3600;
// Spring stiffness of a drag or curve when the script gives no k=, N/m.
constexpr double kDefaultDragStiffness = 2e4;

struct NameInfo {
  int line;
  bool is_load;  // a load (force, pressure) or a constraint (fix)
};

class LineParser;
// A verb's parser (below): the line's arguments in, the parsed line out.
using VerbParser = void (*)(LineParser& p, ScriptLine& out);

// What a verb accepts, and its parser.
struct VerbSpec {
  const char* verb;
  std::vector<std::string> keys;  // key=value keys it accepts
  const char* positional;         // the key a bare value stands for, or nullptr
  VerbParser parse;
};

// A name given with name=, or referenced by remove / unfix.
bool ValidName(absl::string_view s) {
  if (s.empty() || s.size() > 64) return false;
  if (!absl::ascii_isalpha(s[0]) && s[0] != '_') return false;
  for (char c : s) {
    if (!absl::ascii_isalnum(c) && c != '_' && c != '-' && c != '.') return false;
  }
  return true;
}

// One line being parsed: its key=value arguments, the names bound by
// earlier lines and the error, if any.
class LineParser {
 public:
  LineParser(const VerbSpec& spec, std::map<std::string, std::string> args,
             std::map<std::string, NameInfo>& names)
      : spec_(spec), args_(std::move(args)), names_(names) {}

  bool Has(const std::string& key) const { return args_.count(key) > 0; }
  const std::string& Value(const std::string& key) const { return args_.at(key); }
  const std::string& error() const { return error_; }
  bool ok() const { return error_.empty(); }

  // "key=value" as the user wrote it (a positional value is shown bare).
  std::string Token(const std::string& key) const {
    auto it = args_.find(key);
    if (it == args_.end()) return key;
    if (spec_.positional != nullptr && key == spec_.positional && positional_) {
      return it->second;
    }
    return absl::StrCat(key, "=", it->second);
  }
  void set_positional(bool p) { positional_ = p; }

  void Fail(std::string message) {
    if (error_.empty()) error_ = absl::StrCat(spec_.verb, ": ", message);
  }

  // Numbers of key (comma separated); `count` of them, each finite.
  std::optional<std::vector<double>> Numbers(const std::string& key, int count) {
    if (!ok()) return std::nullopt;
    const std::string& value = args_.at(key);
    std::vector<std::string> parts = absl::StrSplit(value, ',');
    if (static_cast<int>(parts.size()) != count) {
      Fail(absl::StrCat("\"", Token(key), "\" needs ", count, count == 1 ? " number" : " numbers",
                        ", got ", parts.size()));
      return std::nullopt;
    }
    std::vector<double> out;
    for (const std::string& p : parts) {
      double v = 0;
      if (p.empty() || !absl::SimpleAtod(p, &v) || p != absl::StripAsciiWhitespace(p)) {
        Fail(absl::StrCat("bad number \"", p, "\" in \"", Token(key), "\""));
        return std::nullopt;
      }
      if (!std::isfinite(v)) {
        Fail(absl::StrCat("\"", p, "\" in \"", Token(key), "\" is not a finite number"));
        return std::nullopt;
      }
      out.push_back(v);
    }
    return out;
  }
  std::optional<double> Number(const std::string& key) {
    auto v = Numbers(key, 1);
    if (!v) return std::nullopt;
    return (*v)[0];
  }
  std::optional<int64_t> Integer(const std::string& key, int64_t lo, int64_t hi) {
    if (!ok()) return std::nullopt;
    const std::string& value = args_.at(key);
    int64_t v = 0;
    if (value.empty() || !absl::SimpleAtoi(value, &v) || v < lo || v > hi) {
      Fail(absl::StrCat("\"", Token(key), "\" must be an integer in [", lo, ", ", hi, "]"));
      return std::nullopt;
    }
    return v;
  }
  void Require(const std::string& key, const char* what) {
    if (ok() && !Has(key)) Fail(absl::StrCat("missing ", key, "=", what));
  }
  static void SetVec(Vec3* out, const std::vector<double>& v, int at = 0) {
    out->set_x(v[at]);
    out->set_y(v[at + 1]);
    out->set_z(v[at + 2]);
  }

  // Comma-separated integers >= 0 ("1,2,5"); at least one.
  std::optional<std::vector<int32_t>> Indices(const std::string& key) {
    if (!ok()) return std::nullopt;
    std::vector<int32_t> out;
    for (absl::string_view part : absl::StrSplit(args_.at(key), ',')) {
      int32_t i = 0;
      if (part.empty() || !absl::SimpleAtoi(part, &i) || i < 0) {
        Fail(absl::StrCat("bad index \"", part, "\" in \"", Token(key), "\" (integers >= 0)"));
        return std::nullopt;
      }
      out.push_back(i);
    }
    return out;
  }
  // A polyline "X,Y,Z/X,Y,Z/..." (at least 2 points).
  std::optional<std::vector<std::vector<double>>> Polyline(const std::string& key) {
    return Points(key, 2);
  }
  // Points "X,Y,Z/X,Y,Z/..." (at least `min`).
  std::optional<std::vector<std::vector<double>>> Points(const std::string& key, size_t min = 1) {
    if (!ok()) return std::nullopt;
    std::vector<std::vector<double>> out;
    const std::string all = args_.at(key);
    for (absl::string_view point : absl::StrSplit(all, '/')) {
      std::vector<double> xyz;
      for (absl::string_view part : absl::StrSplit(point, ',')) {
        double v = 0;
        if (part.empty() || !absl::SimpleAtod(part, &v) || !std::isfinite(v)) {
          Fail(absl::StrCat("bad number \"", part, "\" in \"", Token(key), "\""));
          return std::nullopt;
        }
        xyz.push_back(v);
      }
      if (xyz.size() != 3) {
        Fail(absl::StrCat("\"", Token(key), "\": each point needs 3 numbers (X,Y,Z/X,Y,Z/...)"));
        return std::nullopt;
      }
      out.push_back(std::move(xyz));
    }
    if (out.size() < min) {
      Fail(absl::StrCat("\"", Token(key), "\": needs at least ", min, " points"));
      return std::nullopt;
    }
    return out;
  }

  // box= / sphere= / cells= into `region`; `required`: one must be given.
  void ParseRegion(Region* region) {
    if (!ok()) return;
    if (!Has("box") && !Has("sphere") && !Has("cells")) {
      Fail("needs a region: box=X0,Y0,Z0,X1,Y1,Z1, sphere=X,Y,Z,R and/or cells=I,J,...");
      return;
    }
    if (Has("box") && Has("sphere")) {
      Fail(absl::StrCat("\"", Token("box"), "\" and \"", Token("sphere"),
                        "\": a region has one shape (box or sphere)"));
      return;
    }
    if (Has("box")) {
      auto v = Numbers("box", 6);
      if (!v) return;
      static const char* kAxis[] = {"x", "y", "z"};
      for (int a = 0; a < 3; ++a) {
        if ((*v)[a] > (*v)[a + 3]) {
          Fail(absl::StrCat("\"", Token("box"), "\": min exceeds max on ", kAxis[a], " (",
                            (*v)[a], " > ", (*v)[a + 3], ")"));
          return;
        }
      }
      SetVec(region->mutable_box()->mutable_min(), *v, 0);
      SetVec(region->mutable_box()->mutable_max(), *v, 3);
    }
    if (Has("sphere")) {
      auto v = Numbers("sphere", 4);
      if (!v) return;
      if ((*v)[3] <= 0) {
        Fail(absl::StrCat("\"", Token("sphere"), "\": the radius must be > 0, got ", (*v)[3]));
        return;
      }
      SetVec(region->mutable_sphere()->mutable_center(), *v, 0);
      region->mutable_sphere()->set_radius((*v)[3]);
    }
    if (Has("cells")) {
      const std::string& value = args_.at("cells");
      for (absl::string_view p : absl::StrSplit(value, ',')) {
        int32_t c = 0;
        if (p.empty() || !absl::SimpleAtoi(p, &c) || c < 0) {
          Fail(absl::StrCat("bad cell index \"", p, "\" in \"", Token("cells"),
                            "\" (integers >= 0)"));
          return;
        }
        region->add_control_cells(c);
      }
    }
  }

  // name=NAME on force / pressure / fix / drag / curve.
  void BindName(ScriptLine& out, bool is_load) {
    if (!ok() || !Has("name")) return;
    const std::string token = Token("name");
    const std::string name = Value("name");
    if (!ValidName(name)) {
      Fail(absl::StrCat("bad name in \"", token,
                        "\" (a letter or _, then letters, digits, _ - .; at most 64)"));
      return;
    }
    auto it = names_.find(name);
    if (it != names_.end()) {
      Fail(absl::StrCat("name \"", name, "\" already used at line ", it->second.line));
      return;
    }
    out.name = name;
    names_[name] = NameInfo{out.line, is_load};
  }
  // load=NAME|ID, constraint=NAME|ID.
  void Reference(ScriptLine& out, const std::string& key, bool want_load, int64_t* id) {
    Require(key, "NAME|ID");
    if (!ok()) return;
    const std::string token = Token(key);
    const std::string value = Value(key);
    int64_t n = 0;
    if (absl::SimpleAtoi(value, &n)) {
      if (n < 1) Fail(absl::StrCat("\"", token, "\": an id is >= 1"));
      *id = n;
      return;
    }
    auto it = names_.find(value);
    const char* want = want_load ? "load" : "constraint";
    if (it == names_.end()) {
      Fail(absl::StrCat("unknown ", want, " \"", value, "\" in \"", token, "\" (no earlier ",
                        want_load ? "force or pressure" : "fix", " has name=", value, ")"));
      return;
    }
    if (it->second.is_load != want_load) {
      Fail(absl::StrCat("\"", token, "\" names a ", want_load ? "constraint" : "load",
                        " (line ", it->second.line, "), not a ", want));
      return;
    }
    out.ref = value;
  }

 private:
  const VerbSpec& spec_;
  std::map<std::string, std::string> args_;
  std::map<std::string, NameInfo>& names_;
  bool positional_ = false;
  std::string error_;
};

// The verbs' parsers, one a verb (a few share one): each reads the line's
// arguments from `p` into `out` (its command, or a client-side action) and
// leaves the first error in `p`.

void ParseForce(LineParser& p, ScriptLine& out) {
  p.Require("at", "X,Y,Z");
  p.Require("f", "FX,FY,FZ");
  PointForce* f = out.command.mutable_add_point_force();
  if (auto v = p.Numbers("at", 3)) LineParser::SetVec(f->mutable_position(), *v);
  if (auto v = p.Numbers("f", 3)) LineParser::SetVec(f->mutable_force(), *v);
  p.BindName(out, true);
}

void ParsePressure(LineParser& p, ScriptLine& out) {
  Pressure* pr = out.command.mutable_add_pressure();
  p.ParseRegion(pr->mutable_region());
  p.Require("pa", "PASCALS");
  if (auto v = p.Number("pa")) {
    if (*v == 0) p.Fail(absl::StrCat("\"", p.Token("pa"), "\": pascals must be non-zero"));
    pr->set_pascals(*v);
  }
  p.BindName(out, true);
}

void ParseGravity(LineParser& p, ScriptLine& out) {
  p.Require("g", "GX,GY,GZ");
  if (auto v = p.Numbers("g", 3)) LineParser::SetVec(out.command.mutable_set_gravity(), *v);
}

// remove and release: a force or pressure, or a drag or curve (loads too).
void ParseRemoveLoad(LineParser& p, ScriptLine& out) {
  int64_t id = 0;
  p.Reference(out, "load", true, &id);
  out.command.mutable_remove_load()->set_load_id(id);
}

void ParseFix(LineParser& p, ScriptLine& out) {
  p.ParseRegion(out.command.mutable_fix_region());
  p.BindName(out, false);
}

void ParseUnfix(LineParser& p, ScriptLine& out) {
  int64_t id = 0;
  p.Reference(out, "constraint", false, &id);
  out.command.mutable_unfix()->set_constraint_id(id);
}

void ParsePaint(LineParser& p, ScriptLine& out) {
  MaterialPaint* paint = out.command.mutable_paint_material();
  p.ParseRegion(paint->mutable_region());
  Material* m = paint->mutable_material();
  if (p.ok() && !p.Has("E") && !p.Has("nu") && !p.Has("density") && !p.Has("damping") &&
      !p.Has("preset") && !p.Has("yield") && !p.Has("flow") && !p.Has("hardening")) {
    p.Fail(
        "needs at least one of E=PASCALS, nu=RATIO, density=KG_M3, damping=KG_M3_S, "
        "preset=rubber|clay|wax, yield=STRAIN, flow=PER_SECOND, hardening=RATIO");
  }
  if (p.ok() && p.Has("preset")) {
    const std::string name = absl::AsciiStrToLower(p.Value("preset"));
    Material::Preset preset = Material::PRESET_NONE;
    if (name == "rubber") {
      preset = Material::RUBBER;
    } else if (name == "clay") {
      preset = Material::CLAY;
    } else if (name == "wax") {
      preset = Material::WAX;
    } else {
      p.Fail(absl::StrCat("\"", p.Token("preset"), "\" is not a preset: rubber, clay or wax"));
    }
    m->set_preset(preset);
  }
  if (p.ok() && p.Has("yield")) {
    if (auto v = p.Number("yield")) {
      if (*v < 0 || *v >= 1) p.Fail(absl::StrCat("\"", p.Token("yield"), "\" must be in [0, 1)"));
      m->set_yield_strain(*v);
    }
  }
  auto non_negative = [&](const std::string& key, void (Material::*set)(double)) {
    if (!p.ok() || !p.Has(key)) return;
    if (auto v = p.Number(key)) {
      if (*v < 0) p.Fail(absl::StrCat("\"", p.Token(key), "\" must be >= 0"));
      (m->*set)(*v);
    }
  };
  non_negative("E", &Material::set_young_modulus);
  non_negative("density", &Material::set_density);
  non_negative("damping", &Material::set_damping);
  non_negative("flow", &Material::set_flow_rate);
  non_negative("hardening", &Material::set_hardening);
  if (p.ok() && p.Has("nu")) {
    if (auto v = p.Number("nu")) {
      if (*v < 0 || *v >= 0.5) p.Fail(absl::StrCat("\"", p.Token("nu"), "\" must be in [0, 0.5)"));
      m->set_poisson_ratio(*v);
    }
  }
  paint->set_strength(1);
  if (p.ok() && p.Has("strength")) {
    if (auto v = p.Number("strength")) {
      if (*v <= 0 || *v > 1) {
        p.Fail(absl::StrCat("\"", p.Token("strength"), "\" must be in (0, 1]"));
      }
      paint->set_strength(*v);
    }
  }
  if (p.ok() && p.Has("falloff")) {
    if (auto v = p.Number("falloff")) {
      if (*v < 0 || *v > 1) p.Fail(absl::StrCat("\"", p.Token("falloff"), "\" must be in [0, 1]"));
      paint->set_falloff(*v);
    }
  }
}

void ParseDrag(LineParser& p, ScriptLine& out) {
  p.Require("at", "X,Y,Z");
  p.Require("to", "X,Y,Z");
  Drag* d = out.command.mutable_drag();
  if (auto v = p.Numbers("at", 3)) LineParser::SetVec(d->mutable_material_point(), *v);
  if (auto v = p.Numbers("to", 3)) LineParser::SetVec(d->mutable_target(), *v);
  d->set_stiffness(kDefaultDragStiffness);
  if (p.ok() && p.Has("k")) {
    if (auto v = p.Number("k")) {
      if (*v <= 0) p.Fail(absl::StrCat("\"", p.Token("k"), "\" must be > 0 N/m"));
      d->set_stiffness(*v);
    }
  }
  p.BindName(out, true);
}

void ParseCurve(LineParser& p, ScriptLine& out) {
  p.Require("along", "X,Y,Z/X,Y,Z/...");
  p.Require("to", "X,Y,Z/X,Y,Z/...");
  CurveDrag* cd = out.command.mutable_curve();
  auto along = p.Polyline("along");
  auto to = p.Polyline("to");
  if (along && to && along->size() != to->size()) {
    p.Fail(absl::StrCat("\"", p.Token("to"), "\" has ", to->size(), " points, \"along=\" has ",
                        along->size()));
  }
  if (p.ok()) {
    for (const auto& v : *along) LineParser::SetVec(cd->add_material_points(), v);
    for (const auto& v : *to) LineParser::SetVec(cd->add_targets(), v);
  }
  cd->set_stiffness(kDefaultDragStiffness);
  if (p.ok() && p.Has("k")) {
    if (auto v = p.Number("k")) {
      if (*v <= 0) p.Fail(absl::StrCat("\"", p.Token("k"), "\" must be > 0 N/m"));
      cd->set_stiffness(*v);
    }
  }
  if (p.ok() && p.Has("samples")) {
    if (auto n = p.Integer("samples", 2, 256)) cd->set_samples(static_cast<int32_t>(*n));
  }
  p.BindName(out, true);
}

void ParseMove(LineParser& p, ScriptLine& out) {
  int64_t id = 0;
  p.Reference(out, "load", true, &id);
  p.Require("to", "X,Y,Z or X,Y,Z/X,Y,Z/...");
  MoveDrag* m = out.command.mutable_move_drag();
  m->set_load_id(id);
  if (p.ok()) {
    if (absl::StrContains(p.Value("to"), '/')) {
      if (auto line = p.Polyline("to")) {
        for (const auto& v : *line) LineParser::SetVec(m->add_targets(), v);
      }
    } else if (auto v = p.Numbers("to", 3)) {
      LineParser::SetVec(m->mutable_target(), *v);
    }
  }
}

// delete and subdivide: the same arguments, another edit.
void ParseCellEdit(LineParser& p, ScriptLine& out) {
  Command& c = out.command;
  const bool del = out.verb == "delete";
  if (p.ok() && !p.Has("cells") && !p.Has("near")) p.Fail("needs cells=I,J,... or near=X,Y,Z/...");
  auto* cells = del ? c.mutable_edit()->mutable_delete_cells()->mutable_cells()
                    : c.mutable_edit()->mutable_subdivide_cells()->mutable_cells();
  auto* near = del ? c.mutable_edit()->mutable_delete_cells()->mutable_near()
                   : c.mutable_edit()->mutable_subdivide_cells()->mutable_near();
  if (p.ok() && p.Has("cells")) {
    if (auto v = p.Indices("cells")) cells->Add(v->begin(), v->end());
  }
  if (p.ok() && p.Has("near")) {
    if (auto v = p.Points("near")) {
      for (const auto& x : *v) LineParser::SetVec(near->Add(), x);
    }
  }
}

void ParseExtrude(LineParser& p, ScriptLine& out) {
  if (p.ok() && !p.Has("faces") && !p.Has("near")) p.Fail("needs faces=I,J,... or near=X,Y,Z/...");
  p.Require("d", "METRES");
  ExtrudeFaces* x = out.command.mutable_edit()->mutable_extrude_faces();
  if (p.ok() && p.Has("faces")) {
    if (auto v = p.Indices("faces")) x->mutable_faces()->Add(v->begin(), v->end());
  }
  if (p.ok() && p.Has("near")) {
    if (auto v = p.Points("near")) {
      for (const auto& y : *v) LineParser::SetVec(x->add_near(), y);
    }
  }
  if (auto v = p.Number("d")) {
    if (*v <= 0) p.Fail(absl::StrCat("\"", p.Token("d"), "\" must be > 0 metres"));
    x->set_distance(*v);
  }
  x->set_layers(1);
  if (p.ok() && p.Has("layers")) {
    if (auto n = p.Integer("layers", 1, 16)) x->set_layers(static_cast<int32_t>(*n));
  }
}

// merge near=P/Q (a point on each face) or faces=A,B.
void ParseMerge(LineParser& p, ScriptLine& out) {
  Command& c = out.command;
  if (p.Has("near")) {
    if (auto v = p.Points("near")) {
      if (v->size() != 2) {
        p.Fail(absl::StrCat("\"", p.Token("near"), "\" needs two points, got ", v->size()));
      } else {
        for (const auto& x : *v) LineParser::SetVec(c.mutable_edit()->mutable_merge_faces()->add_near(), x);
      }
    }
    return;
  }
  p.Require("faces", "A,B");
  if (auto v = p.Indices("faces")) {
    if (v->size() != 2) {
      p.Fail(absl::StrCat("\"", p.Token("faces"), "\" needs two faces, got ", v->size()));
    } else {
      c.mutable_edit()->mutable_merge_faces()->set_face_a((*v)[0]);
      c.mutable_edit()->mutable_merge_faces()->set_face_b((*v)[1]);
    }
  }
}

// sharp and smooth: the same edges, made sharp or smooth again.
void ParseSharpEdges(LineParser& p, ScriptLine& out) {
  p.Require("edges", "V0-V1,V2-V3,...");
  SharpEdges* e = out.command.mutable_edit()->mutable_sharp_edges();
  e->set_sharp(out.verb == "sharp");
  if (p.ok()) {
    for (absl::string_view pair : absl::StrSplit(p.Value("edges"), ',')) {
      std::vector<absl::string_view> ends = absl::StrSplit(pair, '-');
      int32_t a = 0, b = 0;
      if (ends.size() != 2 || !absl::SimpleAtoi(ends[0], &a) || !absl::SimpleAtoi(ends[1], &b) ||
          a < 0 || b < 0) {
        p.Fail(absl::StrCat("bad edge \"", pair, "\" in \"", p.Token("edges"),
                            "\" (control vertex pairs V0-V1)"));
        break;
      }
      EdgeRef* r = e->add_edges();
      r->set_v0(a);
      r->set_v1(b);
    }
  }
}

// The verbs without arguments.
void ParseBake(LineParser&, ScriptLine& out) {
  out.command.mutable_edit()->mutable_bake();  // the server fills in the positions
}
void ParseUndo(LineParser&, ScriptLine& out) { out.command.mutable_undo(); }
void ParseRedo(LineParser&, ScriptLine& out) { out.command.mutable_redo(); }
void ParseRevert(LineParser&, ScriptLine& out) {
  out.command.mutable_revert_to_scene();  // back to the session's scene, undoably
}
void ParsePause(LineParser&, ScriptLine& out) { out.command.mutable_pause(); }
void ParseResume(LineParser&, ScriptLine& out) { out.command.mutable_resume(); }
void ParseSave(LineParser&, ScriptLine& out) { out.command.mutable_save(); }

void ParseStep(LineParser& p, ScriptLine& out) {
  p.Require("count", "N");
  if (auto n = p.Integer("count", 1, kMaxStepCount)) out.command.mutable_step()->set_count(*n);
}

// wait N / wait_until N: a client-side wait for a step (`kind`), N in `key`.
void WaitFor(LineParser& p, ScriptLine& out, const std::string& key, ScriptLine::Kind kind) {
  p.Require(key, "N");
  out.kind = kind;
  out.command.Clear();
  if (auto n = p.Integer(key, 0, int64_t{1} << 50)) out.steps = *n;
}

void ParseWait(LineParser& p, ScriptLine& out) {
  if (!p.Has("steps")) {
    out.kind = ScriptLine::Kind::kWaitSteps;
    out.command.Clear();
    return;
  }
  WaitFor(p, out, "steps", ScriptLine::Kind::kWait);
}

void ParseWaitUntil(LineParser& p, ScriptLine& out) {
  WaitFor(p, out, "step", ScriptLine::Kind::kWaitUntil);
}

void ParseSleep(LineParser& p, ScriptLine& out) {
  p.Require("seconds", "SECONDS");
  out.kind = ScriptLine::Kind::kSleep;
  out.command.Clear();
  if (auto v = p.Number("seconds")) {
    if (*v < 0 || *v > kMaxSleepSeconds) {
      p.Fail(absl::StrCat("\"", p.Token("seconds"), "\" must be in [0, ", kMaxSleepSeconds,
                          "] seconds"));
    }
    out.seconds = *v;
  }
}

void ParseSnapshot(LineParser& p, ScriptLine& out) {
  out.kind = ScriptLine::Kind::kSnapshot;
  out.command.Clear();
  if (p.Has("name")) {
    const std::string token = p.Token("name");
    const std::string name = p.Value("name");
    if (!ValidName(name)) {
      p.Fail(absl::StrCat("bad name \"", token,
                          "\" (a letter or _, then letters, digits, _ - .; at most 64)"));
    }
    out.name = name;
  } else {
    out.name = absl::StrCat("snapshot_line", out.line);
  }
}

const std::vector<std::string> kRegionKeys = {"box", "sphere", "cells"};

std::vector<std::string> Cat(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// The verbs, in the order the unknown-command message lists them.
const std::vector<VerbSpec>& Verbs() {
  static const std::vector<VerbSpec>* verbs = new std::vector<VerbSpec>{
      {"force", {"at", "f", "name"}, nullptr, ParseForce},
      {"pressure", Cat(kRegionKeys, {"pa", "name"}), nullptr, ParsePressure},
      {"gravity", {"g"}, "g", ParseGravity},
      {"remove", {"load"}, "load", ParseRemoveLoad},
      {"fix", Cat(kRegionKeys, {"name"}), nullptr, ParseFix},
      {"unfix", {"constraint"}, "constraint", ParseUnfix},
      {"paint", Cat(kRegionKeys, {"E", "nu", "density", "damping", "preset", "yield", "flow",
                                  "hardening", "strength", "falloff"}),
       nullptr, ParsePaint},
      {"drag", {"at", "to", "k", "name"}, nullptr, ParseDrag},
      {"curve", {"along", "to", "k", "samples", "name"}, nullptr, ParseCurve},
      {"move", {"load", "to"}, "load", ParseMove},
      {"release", {"load"}, "load", ParseRemoveLoad},
      {"delete", {"cells", "near"}, "cells", ParseCellEdit},
      {"extrude", {"faces", "near", "d", "layers"}, "faces", ParseExtrude},
      {"merge", {"faces", "near"}, "faces", ParseMerge},
      {"subdivide", {"cells", "near"}, "cells", ParseCellEdit},
      {"sharp", {"edges"}, "edges", ParseSharpEdges},
      {"smooth", {"edges"}, "edges", ParseSharpEdges},
      {"bake", {}, nullptr, ParseBake},
      {"undo", {}, nullptr, ParseUndo},
      {"redo", {}, nullptr, ParseRedo},
      {"revert", {}, nullptr, ParseRevert},
      {"pause", {}, nullptr, ParsePause},
      {"resume", {}, nullptr, ParseResume},
      {"step", {"count"}, "count", ParseStep},
      {"save", {}, nullptr, ParseSave},
      {"wait", {"steps"}, "steps", ParseWait},
      {"wait_until", {"step"}, "step", ParseWaitUntil},
      {"sleep", {"seconds"}, "seconds", ParseSleep},
      {"snapshot", {"name"}, "name", ParseSnapshot},
  };
  return *verbs;
}

const VerbSpec* FindVerb(const std::string& verb) {
  for (const VerbSpec& v : Verbs()) {
    if (verb == v.verb) return &v;
  }
  return nullptr;
}

std::string VerbList() {
  std::vector<std::string> names;
  for (const VerbSpec& v : Verbs()) names.push_back(v.verb);
  return absl::StrJoin(names, ", ");
}

// The words after the verb into `args` (key -> value; a bare value under
// the verb's positional key, `positional` then true); returns the error
// message ("" when fine).
std::string SplitArgs(const VerbSpec& spec, const std::vector<std::string>& words,
                      std::map<std::string, std::string>* args, bool* positional) {
  const std::string& verb = words[0];
  for (size_t i = 1; i < words.size(); ++i) {
    const std::string& w = words[i];
    const size_t eq = w.find('=');
    std::string key, value;
    if (eq == std::string::npos) {
      if (spec.positional == nullptr) {
        return absl::StrCat(verb, ": unexpected argument \"", w, "\"",
                            spec.keys.empty()
                                ? " (takes none)"
                                : absl::StrCat(" (keys: ", absl::StrJoin(spec.keys, ", "), ")"));
      }
      if (*positional) return absl::StrCat(verb, ": unexpected second value \"", w, "\"");
      *positional = true;
      key = spec.positional;
      value = w;
    } else {
      key = w.substr(0, eq);
      value = w.substr(eq + 1);
      bool known = false;
      for (const std::string& k : spec.keys) known = known || k == key;
      if (!known) {
        return absl::StrCat(verb, ": unknown key \"", key, "\" in \"", w, "\"",
                            spec.keys.empty()
                                ? " (takes no arguments)"
                                : absl::StrCat(" (keys: ", absl::StrJoin(spec.keys, ", "), ")"));
      }
    }
    if (args->count(key) > 0) {
      return absl::StrCat(verb, ": ", key, " given twice (\"", w, "\")");
    }
    (*args)[key] = value;
  }
  return "";
}

// Parses the words of one line (verb first) into `out`; returns the error
// message ("" when fine). `names`: names bound by earlier lines.
std::string ParseLine(const std::vector<std::string>& words,
                      std::map<std::string, NameInfo>& names, ScriptLine& out) {
  const std::string& verb = words[0];
  const VerbSpec* spec = FindVerb(verb);
  if (spec == nullptr) {
    return absl::StrCat("unknown command \"", verb, "\" (commands: ", VerbList(), ")");
  }
  out.verb = verb;
  std::map<std::string, std::string> args;
  bool positional = false;
  if (std::string error = SplitArgs(*spec, words, &args, &positional); !error.empty()) return error;
  LineParser p(*spec, std::move(args), names);
  p.set_positional(positional);
  out.kind = ScriptLine::Kind::kCommand;
  spec->parse(p, out);
  return p.error();
}

}  // namespace

std::string Script::Where(const ScriptLine& l) const { return absl::StrCat(file, ":", l.line); }

absl::StatusOr<Script> ParseScript(absl::string_view text, absl::string_view file) {
  Script script;
  script.file = std::string(file);
  std::vector<std::string> errors;
  std::map<std::string, NameInfo> names;
  int line_number = 0;
  for (absl::string_view raw : absl::StrSplit(text, '\n')) {
    ++line_number;
    absl::string_view line = raw;
    const size_t hash = line.find('#');
    if (hash != absl::string_view::npos) line = line.substr(0, hash);
    std::vector<std::string> words =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r\f\v"), absl::SkipEmpty());
    if (words.empty()) continue;
    ScriptLine out;
    out.line = line_number;
    const std::string error = ParseLine(words, names, out);
    if (!error.empty()) {
      if (static_cast<int>(errors.size()) < kMaxErrors) {
        errors.push_back(absl::StrCat(file, ":", line_number, ": ", error));
      } else if (static_cast<int>(errors.size()) == kMaxErrors) {
        errors.push_back(absl::StrCat(file, ": more errors not shown"));
      }
      continue;
    }
    script.lines.push_back(std::move(out));
  }
  if (!errors.empty()) return absl::InvalidArgumentError(absl::StrJoin(errors, "\n"));
  return script;
}

std::string CommandKindName(const Command& command) {
  const auto* field = Command::descriptor()->FindFieldByNumber(command.kind_case());
  return field == nullptr ? "none" : field->name();
}

}  // namespace dynsolid::client
