#include "clients/lib/surface.h"

#include <charconv>
#include <cmath>
#include <fstream>
#include <utility>

#include "absl/strings/str_cat.h"

namespace dynsolid::client {
namespace {

std::array<double, 3> ToArray(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// Fields of a frame: each empty or `count` values.
absl::Status CheckFields(const SurfaceFields& f, int64_t count, const char* where) {
  const std::pair<const char*, int> sizes[] = {{"displacement", f.displacement_size()},
                                               {"strain", f.strain_size()},
                                               {"stiffness", f.stiffness_size()},
                                               {"mass", f.mass_size()}};
  for (const auto& [name, size] : sizes) {
    if (size != 0 && size != count) {
      return absl::InvalidArgumentError(absl::StrCat(where, ".fields.", name, ": ", size,
                                                     " values for ", count, " vertices"));
    }
  }
  return absl::OkStatus();
}

// Shortest text that reads back as the same double (or float).
template <typename T>
void AppendNumber(std::string& out, T v) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);
  out.append(buffer, result.ptr);
}

absl::Status WriteFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return absl::UnavailableError(absl::StrCat("cannot write ", path));
  out << text;
  out.close();
  if (!out) return absl::UnavailableError(absl::StrCat("cannot write ", path));
  return absl::OkStatus();
}

}  // namespace

std::array<double, 3> Surface::BoundsMin() const {
  std::array<double, 3> m{};
  for (int i = 0; i < vertex_count(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = positions[3 * i + a];
      if (i == 0 || x < m[a]) m[a] = x;
    }
  }
  return m;
}

std::array<double, 3> Surface::BoundsMax() const {
  std::array<double, 3> m{};
  for (int i = 0; i < vertex_count(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = positions[3 * i + a];
      if (i == 0 || x > m[a]) m[a] = x;
    }
  }
  return m;
}

void SurfaceDecoder::Reset() {
  has_keyframe_ = false;
  codes_.clear();
  surface_ = Surface();
}

absl::Status SurfaceDecoder::Apply(const Frame& frame) {
  switch (frame.body_case()) {
    case Frame::kKeyframe:
      return ApplyKeyframe(frame);
    case Frame::kDelta:
      return ApplyDelta(frame);
    default:
      return absl::InvalidArgumentError(
          absl::StrCat("frame at step ", frame.step(), ": neither keyframe nor delta"));
  }
}

absl::Status SurfaceDecoder::ApplyKeyframe(const Frame& frame) {
  const Keyframe& k = frame.keyframe();
  const int64_t n = k.vertex_count();
  if (n < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe.vertex_count: ", n, " is negative"));
  }
  if (k.quads_size() % 4 != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe.quads: ", k.quads_size(), " indices, not a multiple of 4"));
  }
  for (int i = 0; i < k.quads_size(); ++i) {
    if (k.quads(i) < 0 || k.quads(i) >= n) {
      return absl::InvalidArgumentError(absl::StrCat("keyframe.quads[", i, "]: vertex ",
                                                     k.quads(i), " outside [0, ", n, ")"));
    }
  }
  if (static_cast<int64_t>(k.codes().size()) != 6 * n) {
    return absl::InvalidArgumentError(absl::StrCat("keyframe.codes: ", k.codes().size(),
                                                   " bytes for ", n, " vertices (6 each)"));
  }
  if (k.nodes_size() != 0 && k.nodes_size() != n) {
    return absl::InvalidArgumentError(
        absl::StrCat("keyframe.nodes: ", k.nodes_size(), " for ", n, " vertices"));
  }
  const std::array<double, 3> origin = ToArray(k.grid().origin());
  const std::array<double, 3> step = ToArray(k.grid().step());
  for (int a = 0; a < 3; ++a) {
    if (!std::isfinite(origin[a]) || !std::isfinite(step[a]) || step[a] <= 0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "keyframe.grid: origin ", origin[a], " / step ", step[a], " on axis ", a,
          " (steps must be finite and > 0)"));
    }
  }
  if (absl::Status s = CheckFields(k.fields(), n, "keyframe"); !s.ok()) return s;

  codes_.resize(3 * n);
  const auto* bytes = reinterpret_cast<const unsigned char*>(k.codes().data());
  for (int64_t i = 0; i < 3 * n; ++i) {
    codes_[i] = static_cast<uint16_t>(bytes[2 * i] | (bytes[2 * i + 1] << 8));
  }
  origin_ = origin;
  step_ = step;
  has_keyframe_ = true;
  surface_.step = frame.step();
  surface_.time = frame.time();
  surface_.topology_version = k.topology_version();
  surface_.quads.assign(k.quads().begin(), k.quads().end());
  surface_.nodes.assign(k.nodes().begin(), k.nodes().end());
  surface_.displacement.assign(k.fields().displacement().begin(), k.fields().displacement().end());
  surface_.strain.assign(k.fields().strain().begin(), k.fields().strain().end());
  surface_.stiffness.assign(k.fields().stiffness().begin(), k.fields().stiffness().end());
  surface_.mass.assign(k.fields().mass().begin(), k.fields().mass().end());
  surface_.error_bound = ToArray(k.error_bound());
  surface_.positions.resize(3 * n);
  std::vector<int> all(n);
  for (int i = 0; i < n; ++i) all[i] = i;
  DecodePositions(all);
  return absl::OkStatus();
}

absl::Status SurfaceDecoder::ApplyDelta(const Frame& frame) {
  const Delta& d = frame.delta();
  if (!has_keyframe_) {
    return absl::FailedPreconditionError(
        absl::StrCat("delta at step ", frame.step(), " before any keyframe"));
  }
  if (d.base_step() != surface_.step) {
    return absl::FailedPreconditionError(absl::StrCat("delta at step ", frame.step(),
                                                      ": base_step ", d.base_step(),
                                                      " but the last frame was step ",
                                                      surface_.step));
  }
  const int64_t n = surface_.vertex_count();
  // The listed vertices, from the run lengths.
  std::vector<int> listed;
  int64_t at = 0;
  for (int r = 0; r < d.runs_size(); ++r) {
    const int64_t len = d.runs(r);
    if (r % 2 == 1) {
      for (int64_t i = 0; i < len && at + i < n; ++i) listed.push_back(static_cast<int>(at + i));
    }
    at += len;
    if (at > n) {
      return absl::InvalidArgumentError(absl::StrCat("delta.runs: run ", r, " ends at vertex ",
                                                     at, ", past the ", n, " vertices"));
    }
  }
  if (static_cast<int64_t>(listed.size()) != d.moved()) {
    return absl::InvalidArgumentError(absl::StrCat("delta.moved: ", d.moved(), " but runs list ",
                                                   listed.size(), " vertices"));
  }
  if (absl::Status s = CheckFields(d.fields(), d.moved(), "delta"); !s.ok()) return s;
  const std::pair<const char*, std::pair<int, size_t>> field_sizes[] = {
      {"displacement", {d.fields().displacement_size(), surface_.displacement.size()}},
      {"strain", {d.fields().strain_size(), surface_.strain.size()}},
      {"stiffness", {d.fields().stiffness_size(), surface_.stiffness.size()}},
      {"mass", {d.fields().mass_size(), surface_.mass.size()}}};
  for (const auto& [name, sizes] : field_sizes) {
    if (sizes.first != 0 && sizes.second == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("delta.fields.", name, ": present but the keyframe had none"));
    }
  }
  std::vector<uint16_t> updated;
  if (!listed.empty()) {
    const bool rice = d.rice_k_size() > 0;
    const uint32_t bits = d.bits();
    if (rice) {
      if (d.rice_k_size() != 3) {
        return absl::InvalidArgumentError(
            absl::StrCat("delta.rice_k: ", d.rice_k_size(), " values, expected 3 (x, y, z)"));
      }
      for (int a = 0; a < 3; ++a) {
        if (d.rice_k(a) > 16) {
          return absl::InvalidArgumentError(
              absl::StrCat("delta.rice_k[", a, "]: ", d.rice_k(a), " outside [0, 16]"));
        }
      }
    } else {
      if (bits < 1 || bits > 17) {
        return absl::InvalidArgumentError(absl::StrCat("delta.bits: ", bits, " outside [1, 17]"));
      }
      const uint64_t total_bits = uint64_t{3} * listed.size() * bits;
      if (d.packed().size() != (total_bits + 7) / 8) {
        return absl::InvalidArgumentError(absl::StrCat("delta.packed: ", d.packed().size(),
                                                       " bytes, expected ", (total_bits + 7) / 8,
                                                       " for ", listed.size(),
                                                       " vertices at ", bits, " bits"));
      }
    }
    const auto* bytes = reinterpret_cast<const unsigned char*>(d.packed().data());
    const uint64_t size_bits = uint64_t{8} * d.packed().size();
    uint64_t bit = 0;
    bool overrun = false;
    // `n` bits, least significant first (0 past the end, noted).
    auto read = [&](uint32_t n) {
      uint32_t z = 0;
      for (uint32_t b = 0; b < n; ++b, ++bit) {
        if (bit >= size_bits) {
          overrun = true;
          return z;
        }
        z |= static_cast<uint32_t>((bytes[bit >> 3] >> (bit & 7)) & 1u) << b;
      }
      return z;
    };
    updated.reserve(3 * listed.size());
    for (size_t v = 0; v < listed.size(); ++v) {
      for (int a = 0; a < 3; ++a) {
        uint32_t z = 0;
        if (!rice) {
          z = read(bits);
        } else {
          const uint32_t k = d.rice_k(a);
          uint32_t ones = 0;
          while (ones < 16 && read(1) == 1u && !overrun) ++ones;
          // The loop consumed the terminating zero-bit unless it saw 16 ones.
          z = ones < 16 ? (ones << k) | read(k) : read(17);
        }
        if (overrun) {
          return absl::InvalidArgumentError(absl::StrCat(
              "delta.packed: ", d.packed().size(), " bytes end inside vertex ", listed[v],
              " axis ", a, " (", listed.size(), " vertices listed)"));
        }
        const int64_t diff = (z & 1u) ? -static_cast<int64_t>(z >> 1) - 1 : (z >> 1);
        const int64_t code = codes_[3 * listed[v] + a] + diff;
        if (code < 0 || code > 65535) {
          return absl::InvalidArgumentError(
              absl::StrCat("delta.packed: vertex ", listed[v], " axis ", a, " code ", code,
                           " outside [0, 65535]"));
        }
        updated.push_back(static_cast<uint16_t>(code));
      }
    }
    if (rice && d.packed().size() != (bit + 7) / 8) {
      return absl::InvalidArgumentError(absl::StrCat("delta.packed: ", d.packed().size(),
                                                     " bytes, the Rice codes take ", (bit + 7) / 8));
    }
  }
  // Valid: commit.
  for (size_t v = 0; v < listed.size(); ++v) {
    for (int a = 0; a < 3; ++a) codes_[3 * listed[v] + a] = updated[3 * v + a];
  }
  auto set_field = [&](const google::protobuf::RepeatedField<float>& in, std::vector<float>& out) {
    for (int i = 0; i < in.size(); ++i) out[listed[i]] = in[i];
  };
  set_field(d.fields().displacement(), surface_.displacement);
  set_field(d.fields().strain(), surface_.strain);
  set_field(d.fields().stiffness(), surface_.stiffness);
  set_field(d.fields().mass(), surface_.mass);
  surface_.step = frame.step();
  surface_.time = frame.time();
  DecodePositions(listed);
  return absl::OkStatus();
}

void SurfaceDecoder::DecodePositions(const std::vector<int>& which) {
  for (int v : which) {
    for (int a = 0; a < 3; ++a) {
      surface_.positions[3 * v + a] = origin_[a] + codes_[3 * v + a] * step_[a];
    }
  }
}

absl::Status WriteObj(const Surface& s, const std::string& path) {
  std::string text = absl::StrCat("# dynsolid surface, step ", s.step, ", time ", s.time, " s, ",
                                  s.vertex_count(), " vertices, ", s.quads.size() / 4,
                                  " quads\n");
  text.reserve(text.size() + 40 * s.vertex_count() + 30 * s.quads.size() / 4);
  for (int i = 0; i < s.vertex_count(); ++i) {
    text += "v";
    for (int a = 0; a < 3; ++a) {
      text += ' ';
      AppendNumber(text, s.positions[3 * i + a]);
    }
    text += '\n';
  }
  for (size_t q = 0; q + 3 < s.quads.size(); q += 4) {
    absl::StrAppend(&text, "f ", s.quads[q] + 1, " ", s.quads[q + 1] + 1, " ", s.quads[q + 2] + 1,
                    " ", s.quads[q + 3] + 1, "\n");
  }
  return WriteFile(path, text);
}

absl::Status WriteVtu(const Surface& s, const std::string& path) {
  const size_t quads = s.quads.size() / 4;
  std::string t;
  t.reserve(200 + 60 * s.vertex_count() + 40 * quads);
  absl::StrAppend(&t,
                  "<?xml version=\"1.0\"?>\n"
                  "<!-- dynsolid surface, step ",
                  s.step, ", time ", s.time,
                  " s -->\n"
                  "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" "
                  "byte_order=\"LittleEndian\">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"",
                  s.vertex_count(), "\" NumberOfCells=\"", quads, "\">\n<PointData>\n");
  if (!s.nodes.empty()) {
    t += "<DataArray type=\"Int32\" Name=\"node\" format=\"ascii\">\n";
    for (int32_t n : s.nodes) absl::StrAppend(&t, n, "\n");
    t += "</DataArray>\n";
  }
  const std::pair<const char*, const std::vector<float>*> fields[] = {
      {"displacement", &s.displacement},
      {"strain", &s.strain},
      {"stiffness", &s.stiffness},
      {"mass", &s.mass}};
  for (const auto& [name, values] : fields) {
    if (values->empty()) continue;
    absl::StrAppend(&t, "<DataArray type=\"Float32\" Name=\"", name, "\" format=\"ascii\">\n");
    for (float v : *values) {
      AppendNumber(t, v);
      t += '\n';
    }
    t += "</DataArray>\n";
  }
  t += "</PointData>\n<Points>\n"
       "<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (int i = 0; i < s.vertex_count(); ++i) {
    for (int a = 0; a < 3; ++a) {
      AppendNumber(t, s.positions[3 * i + a]);
      t += a < 2 ? ' ' : '\n';
    }
  }
  t += "</DataArray>\n</Points>\n<Cells>\n"
       "<DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  for (size_t q = 0; q < quads; ++q) {
    absl::StrAppend(&t, s.quads[4 * q], " ", s.quads[4 * q + 1], " ", s.quads[4 * q + 2], " ",
                    s.quads[4 * q + 3], "\n");
  }
  t += "</DataArray>\n<DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  for (size_t q = 0; q < quads; ++q) absl::StrAppend(&t, 4 * (q + 1), "\n");
  t += "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (size_t q = 0; q < quads; ++q) t += "9\n";  // VTK_QUAD
  t += "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  return WriteFile(path, t);
}

}  // namespace dynsolid::client
