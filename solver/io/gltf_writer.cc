#include "solver/io/gltf_writer.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "solver/common/json_writer.h"
#include "solver/common/status_macros.h"
#include "solver/io/surface_writers.h"
#include "solver/io/text_file.h"

namespace dynsolid::io {
namespace {

using internal::AppendF32;
using internal::AppendU32;
using internal::Cat;

// glTF constants.
constexpr uint32_t kGlbMagic = 0x46546C67;   // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr int kFloat = 5126;
constexpr int kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
constexpr int kTriangles = 4;

// viridis in sRGB (the web viewer's stops, clients/web/public/js/colormap.js).
constexpr float kViridisStops[][3] = {
    {0.267f, 0.005f, 0.329f}, {0.283f, 0.141f, 0.458f}, {0.254f, 0.265f, 0.530f},
    {0.207f, 0.372f, 0.553f}, {0.164f, 0.471f, 0.558f}, {0.128f, 0.567f, 0.551f},
    {0.135f, 0.659f, 0.518f}, {0.267f, 0.749f, 0.441f}, {0.478f, 0.821f, 0.318f},
    {0.741f, 0.873f, 0.150f}, {0.993f, 0.906f, 0.144f},
};

double SrgbToLinear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

// JSON numbers: shortest text that reads back to the same double. A float
// is written as the double it is exactly (so a reader comparing in double
// or in float32 gets the stored value back).
void JsonNumber(std::string& out, double v) { internal::AppendShortest(out, v); }
void JsonInt(std::string& out, int64_t v) { internal::AppendInt(out, v); }
void JsonVec3(std::string& out, const float v[3]) {
  out.push_back('[');
  for (int k = 0; k < 3; ++k) {
    if (k > 0) out.push_back(',');
    JsonNumber(out, static_cast<double>(v[k]));
  }
  out.push_back(']');
}

struct View {
  size_t offset = 0;
  size_t length = 0;
  int target = 0;
};

// The bounds of a morph target's POSITION offsets.
struct Target {
  float lo[3], hi[3];
};

// The BIN chunk as it is written, and what the JSON says of it: its
// views, in order, the bounds of the positions and of each morph target,
// and the range of the colour field.
struct Bin {
  std::string bytes;
  std::vector<View> views;
  float lo[3] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max(),
                 std::numeric_limits<float>::max()};
  float hi[3] = {-lo[0], -lo[1], -lo[2]};
  double range[2] = {0.0, 0.0};
  std::vector<Target> morph;
};

// The scalar each vertex is coloured by: the value, or the magnitude of a
// field of several components.
absl::Status ColourScalars(const mesh::BoundarySurface& surface, const std::string& name,
                           std::vector<double>& scalars, const mesh::VertexField** found) {
  const mesh::VertexField* field = nullptr;
  for (const mesh::VertexField& f : surface.fields) {
    if (f.name == name) field = &f;
  }
  if (field == nullptr) {
    std::string have;
    for (const mesh::VertexField& f : surface.fields) have += (have.empty() ? "" : ", ") + f.name;
    return absl::InvalidArgumentError(Cat("colour field '", name, "' is not on the surface (",
                                          have.empty() ? "it has no fields" : "it has: " + have,
                                          ")"));
  }
  const int64_t nv = surface.positions.rows();
  const int c = field->components;
  scalars.resize(static_cast<size_t>(nv));
  for (int64_t i = 0; i < nv; ++i) {
    double sum2 = 0.0;
    for (int k = 0; k < c; ++k) {
      const double x = field->values[i * c + k];
      if (!std::isfinite(x)) {
        return absl::InvalidArgumentError(Cat("colour field '", name, "' is not finite at vertex ",
                                              i,
                                              c > 1 ? Cat(" (component ", k, ")") : std::string()));
      }
      sum2 += x * x;
    }
    scalars[i] = c == 1 ? field->values[i] : std::sqrt(sum2);
  }
  *found = field;
  return absl::OkStatus();
}


// The animation's frames: the surface's vertices each, finite and
// within float32, at increasing finite times.
absl::Status CheckAnimation(const GlbOptions& options, int64_t nv) {
  const size_t targets = options.morph_frames.size();
  if (targets > 0 || !options.morph_times.empty()) {
    if (options.morph_times.size() != targets + 1) {
      return absl::InvalidArgumentError(Cat("animation: ", options.morph_times.size(),
                                            " times for ", targets + 1, " frames"));
    }
    for (size_t k = 0; k < options.morph_times.size(); ++k) {
      const double t = options.morph_times[k];
      if (!std::isfinite(t) || (k > 0 && !(t > options.morph_times[k - 1]))) {
        return absl::InvalidArgumentError(
            Cat("animation: frame ", k, "'s time ", t, " is not finite and after the one before"));
      }
    }
    for (size_t k = 0; k < targets; ++k) {
      const Points& f = options.morph_frames[k];
      if (f.rows() != nv || f.cols() != 3) {
        return absl::InvalidArgumentError(Cat("animation: frame ", k + 1, " has ", f.rows(),
                                              " vertices, the surface ", nv));
      }
      if (!f.allFinite() || f.cwiseAbs().maxCoeff() > std::numeric_limits<float>::max()) {
        return absl::InvalidArgumentError(
            Cat("animation: frame ", k + 1, "'s positions are not finite float32 values"));
      }
    }
  }
  return absl::OkStatus();
}

// Vertex normals: the sum over the vertex's fan triangles of their
// (b - a) x (c - a), i.e. normals weighted by area; unit length (a
// vertex on no face or only on degenerate triangles has no normal; glTF
// requires unit normals, so it gets +z). `q` is the surface's positions
// or a frame's.
Points UnitNormals(const mesh::BoundarySurface& surface, const Points& q) {
  const int64_t nv = surface.positions.rows();
  Points normals = Points::Zero(nv, 3);
  internal::ForEachFanTriangle(surface, [&](int32_t ia, int32_t ib, int32_t ic) {
    const Eigen::Vector3d a = q.row(ia).transpose();
    const Eigen::Vector3d b = q.row(ib).transpose();
    const Eigen::Vector3d c = q.row(ic).transpose();
    const Eigen::RowVector3d n = (b - a).cross(c - a).transpose();
    normals.row(ia) += n;
    normals.row(ib) += n;
    normals.row(ic) += n;
  });
  for (int64_t i = 0; i < nv; ++i) {
    const double length = normals.row(i).norm();
    if (length > 0.0 && std::isfinite(length)) {
      normals.row(i) /= length;
    } else {
      normals.row(i) = Eigen::RowVector3d(0, 0, 1);
    }
  }
  return normals;
}

// BIN chunk: positions, normals, colours (with `scalars`, the colour
// field's), indices (all 4-byte multiples).
void AppendSurfaceBuffers(const mesh::BoundarySurface& surface, const Points& normals,
                          const std::vector<double>* scalars, int64_t nt, Bin& bin) {
  const Points& p = surface.positions;
  const int64_t nv = p.rows();
  const size_t vec3_bytes = 12 * static_cast<size_t>(nv);
  const size_t index_bytes = 12 * static_cast<size_t>(nt);
  bin.views.push_back({bin.bytes.size(), vec3_bytes, kArrayBuffer});
  for (int64_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) {
      const float x = static_cast<float>(p(i, k));
      bin.lo[k] = std::min(bin.lo[k], x);
      bin.hi[k] = std::max(bin.hi[k], x);
      AppendF32(bin.bytes, x);
    }
  }
  bin.views.push_back({bin.bytes.size(), vec3_bytes, kArrayBuffer});
  for (int64_t i = 0; i < nv; ++i) {
    for (int k = 0; k < 3; ++k) AppendF32(bin.bytes, static_cast<float>(normals(i, k)));
  }
  if (scalars != nullptr) {
    bin.range[0] = *std::min_element(scalars->begin(), scalars->end());
    bin.range[1] = *std::max_element(scalars->begin(), scalars->end());
    const double span = bin.range[1] - bin.range[0];
    bin.views.push_back({bin.bytes.size(), vec3_bytes, kArrayBuffer});
    for (int64_t i = 0; i < nv; ++i) {
      const double t = span > 0.0 ? ((*scalars)[i] - bin.range[0]) / span : 0.5;
      for (float c : ViridisLinearRgb(t)) AppendF32(bin.bytes, c);
    }
  }
  bin.views.push_back({bin.bytes.size(), index_bytes, kElementArrayBuffer});
  internal::ForEachFanTriangle(surface, [&](int32_t a, int32_t b, int32_t c) {
    AppendU32(bin.bytes, static_cast<uint32_t>(a));
    AppendU32(bin.bytes, static_cast<uint32_t>(b));
    AppendU32(bin.bytes, static_cast<uint32_t>(c));
  });
}

// The animation: per target its POSITION and NORMAL offsets (float32 of
// the double differences) with their bounds, then the key times and the
// weights (frame k: target k - 1 at 1, the rest 0).
void AppendAnimationBuffers(const mesh::BoundarySurface& surface, const Points& normals,
                            const GlbOptions& options, Bin& bin) {
  const Points& p = surface.positions;
  const int64_t nv = p.rows();
  const size_t vec3_bytes = 12 * static_cast<size_t>(nv);
  const size_t targets = options.morph_frames.size();
  bin.morph.resize(targets);
  for (size_t k = 0; k < targets; ++k) {
    const Points& f = options.morph_frames[k];
    const Points fn = UnitNormals(surface, f);
    Target& t = bin.morph[k];
    for (int c = 0; c < 3; ++c) {
      t.lo[c] = std::numeric_limits<float>::max();
      t.hi[c] = -t.lo[c];
    }
    bin.views.push_back({bin.bytes.size(), vec3_bytes, kArrayBuffer});
    for (int64_t i = 0; i < nv; ++i) {
      for (int c = 0; c < 3; ++c) {
        const float d = static_cast<float>(f(i, c) - p(i, c));
        t.lo[c] = std::min(t.lo[c], d);
        t.hi[c] = std::max(t.hi[c], d);
        AppendF32(bin.bytes, d);
      }
    }
    bin.views.push_back({bin.bytes.size(), vec3_bytes, kArrayBuffer});
    for (int64_t i = 0; i < nv; ++i) {
      for (int c = 0; c < 3; ++c) {
        AppendF32(bin.bytes, static_cast<float>(fn(i, c) - normals(i, c)));
      }
    }
  }
  if (targets > 0) {
    bin.views.push_back({bin.bytes.size(), 4 * (targets + 1), 0});
    for (double t : options.morph_times) AppendF32(bin.bytes, static_cast<float>(t));
    bin.views.push_back({bin.bytes.size(), 4 * (targets + 1) * targets, 0});
    for (size_t k = 0; k <= targets; ++k) {
      for (size_t m = 0; m < targets; ++m) {
        AppendF32(bin.bytes, k > 0 && m == k - 1 ? 1.0f : 0.0f);
      }
    }
  }
}

// JSON: the asset, the scene and its node, the material, and the mesh
// with its primitive (its attributes, its morph targets' accessors and the
// colour field in its extras). Accessors follow the views: 0 POSITION,
// 1 NORMAL, [2 COLOR_0], then the indices.
void AppendMeshJson(std::string& j, const GlbOptions& options, const mesh::VertexField* colour,
                    const Bin& bin) {
  const size_t targets = options.morph_frames.size();
  const int index_accessor = colour != nullptr ? 3 : 2;
  j += "{\"asset\":{\"version\":\"2.0\",\"generator\":";
  j += JsonWriter::Quote(options.generator);
  j += "},\"scene\":0,\"scenes\":[{\"name\":\"dynsolid\",\"nodes\":[0]}],";
  j += "\"nodes\":[{\"name\":\"boundary surface\",\"mesh\":0";
  if (options.z_up) {
    // -90 degrees about x: +z (the scenes' up) becomes +y (glTF's up).
    const double h = std::sqrt(0.5);
    j += ",\"rotation\":[";
    JsonNumber(j, -h);
    j += ",0,0,";
    JsonNumber(j, h);
    j += "]";
  }
  j += "}],\"materials\":[{\"name\":\"dynsolid surface\",\"pbrMetallicRoughness\":{";
  j += colour != nullptr ? "\"baseColorFactor\":[1,1,1,1]" : "\"baseColorFactor\":[0.8,0.8,0.8,1]";
  j += ",\"metallicFactor\":0,\"roughnessFactor\":0.7}}],";
  j += "\"meshes\":[{\"name\":\"boundary surface\",\"primitives\":[{\"attributes\":{";
  j += "\"POSITION\":0,\"NORMAL\":1";
  if (colour != nullptr) j += ",\"COLOR_0\":2";
  j += "},\"indices\":";
  JsonInt(j, index_accessor);
  j += ",\"material\":0,\"mode\":";
  JsonInt(j, kTriangles);
  // Morph targets: accessors after the indices, two per target.
  const int first_target = index_accessor + 1;
  if (targets > 0) {
    j += ",\"targets\":[";
    for (size_t k = 0; k < targets; ++k) {
      if (k > 0) j += ",";
      j += "{\"POSITION\":";
      JsonInt(j, first_target + 2 * static_cast<int>(k));
      j += ",\"NORMAL\":";
      JsonInt(j, first_target + 2 * static_cast<int>(k) + 1);
      j += "}";
    }
    j += "]";
  }
  j += "}]";
  if (targets > 0) {
    j += ",\"weights\":[";
    for (size_t k = 0; k < targets; ++k) j += k > 0 ? ",0" : "0";
    j += "]";
  }
  if (colour != nullptr) {
    j += ",\"extras\":{\"color_field\":";
    j += JsonWriter::Quote(colour->name);
    j += ",\"color_field_components\":";
    JsonInt(j, colour->components);
    j += ",\"color_range\":[";
    JsonNumber(j, bin.range[0]);
    j += ",";
    JsonNumber(j, bin.range[1]);
    j += "],\"colormap\":\"viridis\"}";
  }
  j += "}]";
}

// An accessor's object up to its type; the caller adds min and max, if
// any, and closes it.
void AppendAccessor(std::string& j, int view, int component_type, int64_t count,
                    const char* type) {
  j += "{\"bufferView\":";
  JsonInt(j, view);
  j += ",\"componentType\":";
  JsonInt(j, component_type);
  j += ",\"count\":";
  JsonInt(j, count);
  j += ",\"type\":\"";
  j += type;
  j += "\"";
}

// JSON: the accessors (accessor k reads view k), the animation of the
// morph targets' weights, the views and the buffer.
void AppendBufferJson(std::string& j, const GlbOptions& options, const mesh::VertexField* colour,
                      int64_t nv, int64_t nt, const Bin& bin) {
  const size_t targets = options.morph_frames.size();
  const int index_accessor = colour != nullptr ? 3 : 2;
  const int first_target = index_accessor + 1;
  j += ",\"accessors\":[";
  AppendAccessor(j, 0, kFloat, nv, "VEC3");
  j += ",\"min\":";
  JsonVec3(j, bin.lo);
  j += ",\"max\":";
  JsonVec3(j, bin.hi);
  j += "},";
  AppendAccessor(j, 1, kFloat, nv, "VEC3");
  j += "},";
  if (colour != nullptr) {
    AppendAccessor(j, 2, kFloat, nv, "VEC3");
    j += "},";
  }
  AppendAccessor(j, index_accessor, kUnsignedInt, 3 * nt, "SCALAR");
  j += "}";
  // Views after the indices' (index_accessor is also its view): two per
  // target, then the times and the weights.
  for (size_t k = 0; k < targets; ++k) {
    j += ",";
    AppendAccessor(j, first_target + 2 * static_cast<int>(k), kFloat, nv, "VEC3");
    j += ",\"min\":";
    JsonVec3(j, bin.morph[k].lo);
    j += ",\"max\":";
    JsonVec3(j, bin.morph[k].hi);
    j += "},";
    AppendAccessor(j, first_target + 2 * static_cast<int>(k) + 1, kFloat, nv, "VEC3");
    j += "}";
  }
  const int times_accessor = first_target + 2 * static_cast<int>(targets);
  if (targets > 0) {
    j += ",";
    AppendAccessor(j, times_accessor, kFloat, static_cast<int64_t>(targets + 1), "SCALAR");
    j += ",\"min\":[";
    JsonNumber(j, static_cast<double>(static_cast<float>(options.morph_times.front())));
    j += "],\"max\":[";
    JsonNumber(j, static_cast<double>(static_cast<float>(options.morph_times.back())));
    j += "]},";
    AppendAccessor(j, times_accessor + 1, kFloat, static_cast<int64_t>((targets + 1) * targets),
                   "SCALAR");
    j += "}";
  }
  j += "],";
  if (targets > 0) {
    j += "\"animations\":[{\"name\":\"replay\",\"samplers\":[{\"input\":";
    JsonInt(j, times_accessor);
    j += ",\"output\":";
    JsonInt(j, times_accessor + 1);
    j += ",\"interpolation\":\"LINEAR\"}],\"channels\":[{\"sampler\":0,\"target\":{\"node\":0,"
         "\"path\":\"weights\"}}]}],";
  }
  j += "\"bufferViews\":[";
  for (size_t v = 0; v < bin.views.size(); ++v) {
    if (v > 0) j += ",";
    j += "{\"buffer\":0,\"byteOffset\":";
    JsonInt(j, static_cast<int64_t>(bin.views[v].offset));
    j += ",\"byteLength\":";
    JsonInt(j, static_cast<int64_t>(bin.views[v].length));
    if (bin.views[v].target != 0) {
      j += ",\"target\":";
      JsonInt(j, bin.views[v].target);
    }
    j += "}";
  }
  j += "],\"buffers\":[{\"byteLength\":";
  JsonInt(j, static_cast<int64_t>(bin.bytes.size()));
  j += "}]}";
}

// The file: the 12-byte header, the JSON chunk (padded with spaces), the
// BIN chunk.
absl::Status AppendGlbFile(std::string& j, const std::string& bin, std::string* out) {
  while (j.size() % 4 != 0) j.push_back(' ');

  const size_t total = 12 + 8 + j.size() + 8 + bin.size();
  if (total > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(
        Cat("surface needs a GLB of ", total, " bytes: beyond GLB's 4 GiB"));
  }
  std::string& o = *out;
  o.reserve(o.size() + total);
  AppendU32(o, kGlbMagic);
  AppendU32(o, 2);
  AppendU32(o, static_cast<uint32_t>(total));
  AppendU32(o, static_cast<uint32_t>(j.size()));
  AppendU32(o, kChunkJson);
  o += j;
  AppendU32(o, static_cast<uint32_t>(bin.size()));
  AppendU32(o, kChunkBin);
  o += bin;
  return absl::OkStatus();
}

}  // namespace

std::array<float, 3> ViridisLinearRgb(double t) {
  if (!(t > 0.0)) t = 0.0;  // also NaN
  if (t > 1.0) t = 1.0;
  constexpr int kLast = static_cast<int>(std::size(kViridisStops)) - 1;
  const double x = t * kLast;
  const int i = std::min(static_cast<int>(x), kLast - 1);
  const double f = x - i;
  std::array<float, 3> rgb;
  for (int k = 0; k < 3; ++k) {
    const double a = kViridisStops[i][k];
    const double b = kViridisStops[i + 1][k];
    rgb[k] = static_cast<float>(SrgbToLinear(a + f * (b - a)));
  }
  return rgb;
}

absl::Status GlbBytes(const mesh::BoundarySurface& surface, const GlbOptions& options,
                      std::string* out) {
  RETURN_IF_ERROR(internal::CheckSurface(
      surface, {.need_faces = true, .finite_positions = true, .float32_positions = true}));
  const int64_t nv = surface.positions.rows();
  const int64_t nt = internal::FanTriangleCount(surface);

  std::vector<double> scalars;
  const mesh::VertexField* colour = nullptr;
  if (!options.color_field.empty()) {
    RETURN_IF_ERROR(ColourScalars(surface, options.color_field, scalars, &colour));
  }

  // Sizes first: GLB lengths are uint32.
  const size_t vec3_bytes = 12 * static_cast<size_t>(nv);
  const size_t index_bytes = 12 * static_cast<size_t>(nt);
  const size_t bin_bytes = (colour != nullptr ? 3 : 2) * vec3_bytes + index_bytes;
  // The JSON is a few kilobytes; 64 KiB is a generous bound for the check.
  if (bin_bytes + (1u << 16) > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(Cat("surface of ", nv, " vertices and ", nt,
                                          " triangles needs ", bin_bytes,
                                          " bytes of buffer: beyond GLB's 4 GiB"));
  }
  RETURN_IF_ERROR(CheckAnimation(options, nv));

  const Points normals = UnitNormals(surface, surface.positions);
  Bin bin;
  bin.bytes.reserve(bin_bytes);
  AppendSurfaceBuffers(surface, normals, colour != nullptr ? &scalars : nullptr, nt, bin);
  AppendAnimationBuffers(surface, normals, options, bin);
  const size_t targets = options.morph_frames.size();
  if (bin.bytes.size() + (1u << 16) > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(Cat("animation of ", targets + 1, " frames needs ",
                                          bin.bytes.size(), " bytes: beyond GLB's 4 GiB"));
  }
  while (bin.bytes.size() % 4 != 0) bin.bytes.push_back('\0');  // (already aligned)

  std::string j;
  AppendMeshJson(j, options, colour, bin);
  AppendBufferJson(j, options, colour, nv, nt, bin);
  return AppendGlbFile(j, bin.bytes, out);
}

absl::Status WriteGlb(const std::string& path, const mesh::BoundarySurface& surface,
                      const GlbOptions& options) {
  std::string bytes;
  RETURN_IF_ERROR(internal::WithPath(path, GlbBytes(surface, options, &bytes)));
  return internal::WriteFileBytes(path, bytes);
}

}  // namespace dynsolid::io
