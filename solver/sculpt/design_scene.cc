#include "solver/sculpt/design_scene.h"

#include <string>
#include <vector>

#include <google/protobuf/text_format.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "solver/scene/inline_mesh.h"
#include "solver/sculpt/edit_common.h"

namespace dynsolid::sculpt {
namespace {

void SetVec(Vec3* v, const Eigen::Vector3d& x) {
  v->set_x(x.x());
  v->set_y(x.y());
  v->set_z(x.z());
}

}  // namespace

Scene SelfContainedScene(const Scene& before, const scene::Discretization& d) {
  Scene scene = before;
  const mesh::MeshInput input = internal::ToInput(d.control());
  ControlMesh* m = scene.mutable_mesh();
  m->Clear();
  *m->mutable_inline_mesh() = scene::InlineFromMesh(input);
  scene.mutable_subdivision()->set_levels(d.hierarchy.levels);
  SharpFeatures* sharp = scene.mutable_sharp();
  sharp->Clear();
  for (const auto& [a, b] : internal::SharpPairs(d.control(), d.control_sharp)) {
    EdgeRef* e = sharp->add_edges();
    e->set_v0(a);
    e->set_v1(b);
  }
  return scene;
}

Scene DesignScene(const Scene& scene, const solid::Solid& solid) {
  Scene out = SelfContainedScene(scene, solid.discretization());
  out.clear_initial();
  // Loads and pins as they are now (the scene's own ones among them, or
  // not, as the session left them).
  Loads* loads = out.mutable_loads();
  loads->clear_point_forces();
  loads->clear_pressures();
  loads->clear_gravity();
  const Eigen::Vector3d g = solid.gravity();
  if (g.squaredNorm() > 0) SetVec(loads->mutable_gravity(), g);
  for (const solid::Solid::LoadInfo& l : solid.ActiveLoads()) {
    if (l.kind == solid::Solid::LoadInfo::Kind::kPointForce && !l.material_points.empty()) {
      PointForce* f = loads->add_point_forces();
      SetVec(f->mutable_position(), l.material_points.front());
      SetVec(f->mutable_force(), l.force);
    } else if (l.kind == solid::Solid::LoadInfo::Kind::kPressure) {
      Pressure* p = loads->add_pressures();
      *p->mutable_region() = l.region;
      p->set_pascals(l.pascals);
    }
  }
  Constraints* constraints = out.mutable_constraints();
  constraints->clear_fixed();
  for (const solid::Solid::ConstraintInfo& c : solid.ActiveConstraints()) {
    Region* r = constraints->add_fixed();
    for (int32_t v : c.control_points) r->add_control_points(v);
  }
  *out.mutable_design() = solid.SaveDesign();
  const std::string saved = absl::StrCat("Saved from a session at step ", solid.steps(), ", t = ",
                                         solid.time(), " s.");
  out.set_description(out.description().empty() ? saved : absl::StrCat(out.description(), " ", saved));
  return out;
}

std::string SceneText(const Scene& scene, const std::string& header) {
  std::string out;
  for (absl::string_view line : absl::StrSplit(header, '\n', absl::SkipEmpty())) {
    absl::StrAppend(&out, "# ", line, "\n");
  }
  google::protobuf::TextFormat::Printer printer;
  printer.SetUseShortRepeatedPrimitives(true);
  std::string text;
  printer.PrintToString(scene, &text);
  return out + text;
}

}  // namespace dynsolid::sculpt
