// The rules of one concept (scene_loader.h): every value finite and every
// enum known (ValidateValues), regions, point forces, pressures, material
// paints and materials. ValidateScene applies them to a scene's fields and
// the solid's runtime commands to their own, so each is written once.
// They live apart from scene_loader.cc, which parses, loads and checks
// whole scenes.
#include <cmath>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/common/status_macros.h"
#include "solver/scene/scene_loader.h"

namespace dynsolid::scene {
namespace {

using google::protobuf::FieldDescriptor;

// Debian's Abseil keeps its own string_view (not std::string_view): the
// public API takes std::string_view and converts for absl::StrCat.
absl::string_view A(std::string_view s) { return absl::string_view(s.data(), s.size()); }

// The same check as scene_loader.cc's (its ValidateScene checks single
// fields with it).
absl::Status CheckFinite(absl::string_view field, double value) {
  if (std::isfinite(value)) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(field, " must be finite, got ", value));
}

// Every double (and float) in `message` and its sub-messages is finite, and
// every enum holds a value its type declares. `path` names `message`
// ("" for the Scene). Fields are visited in field-number order, so the first
// failure is the same every time.
absl::Status CheckValues(const google::protobuf::Message& message, const std::string& path) {
  const google::protobuf::Reflection* reflection = message.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);  // set fields only: zeros are fine
  for (const FieldDescriptor* field : fields) {
    const std::string name = path.empty() ? field->name() : absl::StrCat(path, ".", field->name());
    const bool repeated = field->is_repeated();
    const int count = repeated ? reflection->FieldSize(message, field) : 1;
    for (int i = 0; i < count; ++i) {
      const std::string item = repeated ? absl::StrCat(name, "[", i, "]") : name;
      switch (field->cpp_type()) {
        case FieldDescriptor::CPPTYPE_DOUBLE:
          RETURN_IF_ERROR(CheckFinite(item, repeated
                                                ? reflection->GetRepeatedDouble(message, field, i)
                                                : reflection->GetDouble(message, field)));
          break;
        case FieldDescriptor::CPPTYPE_FLOAT:
          RETURN_IF_ERROR(CheckFinite(item, repeated
                                                ? reflection->GetRepeatedFloat(message, field, i)
                                                : reflection->GetFloat(message, field)));
          break;
        case FieldDescriptor::CPPTYPE_ENUM: {
          const int value = repeated ? reflection->GetRepeatedEnumValue(message, field, i)
                                     : reflection->GetEnumValue(message, field);
          const google::protobuf::EnumDescriptor* type = field->enum_type();
          if (type->FindValueByNumber(value) == nullptr) {
            std::vector<std::string> known;
            for (int v = 0; v < type->value_count(); ++v) {
              known.push_back(
                  absl::StrCat(type->value(v)->name(), " (", type->value(v)->number(), ")"));
            }
            return absl::InvalidArgumentError(absl::StrCat(
                item, " has the unknown value ", value, "; ", type->name(), " is one of ",
                absl::StrJoin(known, ", ")));
          }
          break;
        }
        case FieldDescriptor::CPPTYPE_MESSAGE:
          RETURN_IF_ERROR(CheckValues(repeated ? reflection->GetRepeatedMessage(message, field, i)
                                               : reflection->GetMessage(message, field),
                                      item));
          break;
        default:
          break;
      }
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateRegionImpl(const Region& region, absl::string_view field) {
  switch (region.shape_case()) {
    case Region::kBox: {
      const Vec3& lo = region.box().min();
      const Vec3& hi = region.box().max();
      for (const auto& [axis, a, b] : {std::tuple{"x", lo.x(), hi.x()},
                                       std::tuple{"y", lo.y(), hi.y()},
                                       std::tuple{"z", lo.z(), hi.z()}}) {
        if (!(a <= b)) {
          return absl::InvalidArgumentError(absl::StrCat(field, ".box.min.", axis, " (", a,
                                                         ") must be <= box.max.", axis, " (", b,
                                                         ")"));
        }
      }
      break;
    }
    case Region::kSphere:
      if (!(region.sphere().radius() > 0)) {
        return absl::InvalidArgumentError(absl::StrCat(
            field, ".sphere.radius must be > 0 metres, got ", region.sphere().radius()));
      }
      break;
    case Region::SHAPE_NOT_SET:
      break;
  }
  for (int i = 0; i < region.control_cells_size(); ++i) {
    if (region.control_cells(i) < 0) {
      return absl::InvalidArgumentError(absl::StrCat(field, ".control_cells[", i,
                                                     "] must be a cell index >= 0, got ",
                                                     region.control_cells(i)));
    }
  }
  for (int i = 0; i < region.control_points_size(); ++i) {
    if (region.control_points(i) < 0) {
      return absl::InvalidArgumentError(absl::StrCat(field, ".control_points[", i,
                                                     "] must be a vertex index >= 0, got ",
                                                     region.control_points(i)));
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateValues(const google::protobuf::Message& message, std::string_view field) {
  return CheckValues(message, std::string(field));
}

absl::Status ValidateRegion(const Region& region, std::string_view field) {
  return ValidateRegionImpl(region, A(field));
}

absl::Status ValidateNonEmptyRegion(const Region& region, std::string_view field) {
  RETURN_IF_ERROR(ValidateRegion(region, field));
  if (region.shape_case() == Region::SHAPE_NOT_SET && region.control_cells_size() == 0 &&
      region.control_points_size() == 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        A(field), " is empty: set a box, a sphere, control_cells or control_points"));
  }
  return absl::OkStatus();
}

absl::Status ValidatePointForce(const PointForce& force, std::string_view field) {
  return ValidateValues(force, field);
}

absl::Status ValidatePressure(const Pressure& pressure, std::string_view field) {
  RETURN_IF_ERROR(ValidateValues(pressure, field));
  RETURN_IF_ERROR(ValidateNonEmptyRegion(pressure.region(), absl::StrCat(A(field), ".region")));
  if (pressure.pascals() == 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        A(field), ".pascals must be non-zero (positive inflates, negative deflates), got 0"));
  }
  return absl::OkStatus();
}

absl::Status ValidateMaterialPaint(const MaterialPaint& paint, std::string_view field) {
  RETURN_IF_ERROR(ValidateValues(paint, field));
  RETURN_IF_ERROR(ValidateNonEmptyRegion(paint.region(), absl::StrCat(A(field), ".region")));
  const std::string material = absl::StrCat(A(field), ".material");
  RETURN_IF_ERROR(ValidateMaterial(paint.material(), material));
  const Material& m = paint.material();
  if (m.young_modulus() == 0 && m.poisson_ratio() == 0 && m.density() == 0 && m.damping() == 0 &&
      m.yield_strain() == 0 && m.flow_rate() == 0 && m.hardening() == 0 &&
      m.preset() == Material::PRESET_NONE) {
    return absl::InvalidArgumentError(absl::StrCat(
        material, " sets no field: give young_modulus, poisson_ratio, density, damping, "
                  "yield_strain, flow_rate, hardening or a preset"));
  }
  if (!(paint.strength() > 0 && paint.strength() <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat(A(field), ".strength must be in (0, 1], got ", paint.strength()));
  }
  if (!(paint.falloff() >= 0 && paint.falloff() <= 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        A(field), ".falloff must be in [0, 1] (0: the default 0.25), got ", paint.falloff()));
  }
  return absl::OkStatus();
}

absl::Status ValidateMaterial(const Material& material, std::string_view field) {
  const absl::string_view f = A(field);
  if (!(material.young_modulus() >= 0 && std::isfinite(material.young_modulus()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".young_modulus must be > 0 pascals and finite, or 0 for the default ",
        kDefaultYoungModulus, ", got ", material.young_modulus()));
  }
  if (!(material.poisson_ratio() >= 0 && material.poisson_ratio() < 0.5)) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".poisson_ratio must be in [0, 0.5) (0 means the default ", kDefaultPoissonRatio,
        "; 0.5 is incompressible, which this model cannot represent), got ",
        material.poisson_ratio()));
  }
  if (!(material.density() >= 0 && std::isfinite(material.density()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".density must be > 0 kg/m^3 and finite, or 0 for the default ", kDefaultDensity,
        ", got ", material.density()));
  }
  if (!(material.damping() >= 0 && std::isfinite(material.damping()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".damping must be >= 0 kg/(m^3 s) and finite (0 = no damping), got ",
        material.damping()));
  }
  if (!(material.yield_strain() >= 0 && material.yield_strain() < 1)) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".yield_strain must be in [0, 1) (a strain: 0.01 yields past 1 % stretch; 0 = never "
           "yields), got ",
        material.yield_strain()));
  }
  if (!(material.flow_rate() >= 0 && std::isfinite(material.flow_rate()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".flow_rate must be >= 0 per second and finite (0: the default ", kDefaultFlowRate,
        "), got ", material.flow_rate()));
  }
  if (!(material.hardening() >= 0 && std::isfinite(material.hardening()))) {
    return absl::InvalidArgumentError(absl::StrCat(
        f, ".hardening must be >= 0 and finite (0: perfectly plastic), got ",
        material.hardening()));
  }
  return absl::OkStatus();
}

}  // namespace dynsolid::scene
