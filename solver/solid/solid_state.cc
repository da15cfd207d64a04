// The solid's exact state: SaveState writes every value the next step reads
// (positions, clock, loads, constraints, materials, drags, the integrator's
// history) in a checksummed binary record; a restore is prepared off the
// loop (PrepareState) and installed on it (RestorePreparedAtClock).
#include <algorithm>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>

#include "absl/strings/str_cat.h"
#include "solver/common/status_macros.h"
#include "solver/solid/solid.h"
#include "solver/solid/solid_impl.h"

namespace dynsolid::solid {
namespace {

// FNV-1a 64 over bytes: the state's checksum.
// (Format version 3; one multiply per byte in a single chain: about 1.3 ms
// for block4's painted 0.9 MB, which every undoable command paid.)
uint64_t ByteChecksum(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  return h;
}

// Version 4's mixer (WordChecksum, saved_state.h).
uint64_t Mix64(uint64_t x) {
  x ^= x >> 33;
  x *= 0xff51afd7ed558ccdull;
  x ^= x >> 33;
  x *= 0xc4ceb9fe1a85ec53ull;
  x ^= x >> 33;
  return x;
}

// The checksum a state of format `version` carries (3 or 4).
uint64_t Checksum(uint32_t version, std::string_view bytes) {
  return version == 3 ? ByteChecksum(bytes) : WordChecksum(bytes);
}

// Version 5 ends its payload with the material section (the sample arrays
// and each element's array, which change only when the material does)
// and that section's length; the checksum combines the word checksum of
// what comes before the section with the section's own, which the writer
// keeps from one save to the next (Impl::section_*): a painted
// block's state is about a megabyte of samples, which every undoable
// command saved and summed again.
uint64_t CombinedChecksum(uint64_t before, uint64_t section, uint64_t section_bytes) {
  return Mix64(before ^ Mix64(section ^ Mix64(section_bytes)));
}

// Binary state encoding: fixed-width little-endian values (this build runs
// on little-endian machines only), length-prefixed arrays.
class StateWriter {
 public:
  template <typename T>
  void Put(T v) {
    static_assert(std::is_trivially_copyable_v<T>);
    out.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void Doubles(const double* v, size_t n) {
    Put<uint64_t>(n);
    out.append(reinterpret_cast<const char*>(v), n * sizeof(double));
  }
  void Matrix(const Points& m) {
    Put<int64_t>(m.rows());
    out.append(reinterpret_cast<const char*>(m.data()), m.size() * sizeof(double));
  }
  void Bytes(std::string_view s) {
    Put<uint64_t>(s.size());
    out.append(s.data(), s.size());
  }
  void Vec(const Eigen::Vector3d& v) { Doubles(v.data(), 3); }
  std::string out;
};

// Reads what StateWriter wrote; the first failure is kept (DataLoss naming
// what was being read and where) and later reads return zeros.
class StateReader {
 public:
  explicit StateReader(std::string_view bytes) : b_(bytes) {}
  template <typename T>
  T Get(const char* what) {
    T v{};
    if (Need(sizeof(T), what)) {
      std::memcpy(&v, b_.data() + pos_, sizeof(T));
      pos_ += sizeof(T);
    }
    return v;
  }
  // A count that must be at most `max` (guards allocations).
  int64_t Count(const char* what, int64_t max) {
    const uint64_t n = Get<uint64_t>(what);
    if (ok() && n > static_cast<uint64_t>(max)) {
      Fail(absl::StrCat(what, ": count ", n, " is above the possible ", max));
      return 0;
    }
    return static_cast<int64_t>(n);
  }
  std::vector<double> Doubles(const char* what, int64_t expected = -1) {
    const int64_t n = Count(what, static_cast<int64_t>((b_.size() - pos_) / sizeof(double)));
    if (expected >= 0 && ok() && n != expected) {
      Fail(absl::StrCat(what, ": ", n, " values, expected ", expected));
    }
    std::vector<double> v(ok() ? n : 0);
    if (ok() && !v.empty() && Need(v.size() * sizeof(double), what)) {
      std::memcpy(v.data(), b_.data() + pos_, v.size() * sizeof(double));
      pos_ += v.size() * sizeof(double);
    }
    return v;
  }
  Eigen::Vector3d Vec(const char* what) {
    const std::vector<double> v = Doubles(what, 3);
    return ok() ? Eigen::Vector3d(v[0], v[1], v[2]) : Eigen::Vector3d::Zero();
  }
  Points Matrix(const char* what, int64_t rows) {
    const int64_t n = Get<int64_t>(what);
    Points m;
    if (!ok()) return m;
    if (n != rows) {
      Fail(absl::StrCat(what, ": ", n, " rows, the solid has ", rows));
      return m;
    }
    m.resize(rows, 3);
    if (Need(m.size() * sizeof(double), what)) {
      std::memcpy(m.data(), b_.data() + pos_, m.size() * sizeof(double));
      pos_ += m.size() * sizeof(double);
    }
    return m;
  }
  std::string Bytes(const char* what) {
    const int64_t n = Count(what, static_cast<int64_t>(b_.size() - pos_));
    std::string s;
    if (ok() && Need(n, what)) {
      s.assign(b_.data() + pos_, n);
      pos_ += n;
    }
    return s;
  }
  void Fail(std::string message) {
    if (error_.empty()) error_ = std::move(message);
  }
  bool ok() const { return error_.empty(); }
  bool at_end() const { return pos_ == b_.size(); }
  size_t pos() const { return pos_; }
  absl::Status status() const {
    if (ok()) return absl::OkStatus();
    return absl::DataLossError(absl::StrCat("solid state: ", error_));
  }

 private:
  bool Need(size_t n, const char* what) {
    if (!ok()) return false;
    if (b_.size() - pos_ < n) {
      Fail(absl::StrCat("truncated at byte ", pos_, " while reading ", what, " (", n,
                        " bytes needed, ", b_.size() - pos_, " left)"));
      return false;
    }
    return true;
  }
  std::string_view b_;
  size_t pos_ = 0;
  std::string error_;
};

}  // namespace

// Version 4 (saved_state.h): about 30 times faster than version 3's
// single chain, and any change of a byte still changes its chain.
uint64_t WordChecksum(std::string_view bytes) {
  constexpr uint64_t kPrime = 1099511628211ull;
  uint64_t h[4] = {1469598103934665603ull, 0x9e3779b97f4a7c15ull, 0x632be59bd9b4e019ull,
                   0xbf58476d1ce4e5b9ull};
  const size_t n = bytes.size();
  size_t i = 0;
  for (; i + 32 <= n; i += 32) {
    for (int k = 0; k < 4; ++k) {
      uint64_t w;
      std::memcpy(&w, bytes.data() + i + 8 * k, 8);
      h[k] = (h[k] ^ w) * kPrime;
    }
  }
  for (; i < n; ++i) h[i % 4] = (h[i % 4] ^ static_cast<unsigned char>(bytes[i])) * kPrime;
  uint64_t r = n;
  for (uint64_t x : h) r = Mix64(r ^ Mix64(x));
  return r;
}

// ---- Exact state.

namespace {
constexpr char kStateMagic[8] = {'D', 'S', 'O', 'L', 'I', 'D', 'S', 'T'};
constexpr size_t kHeaderBytes = 8 + 4 + 8 + 8 + 8;  // magic, version, fingerprint, payload size
}  // namespace

std::string Solid::SaveState() const { return JoinState(SaveStateParts()); }

std::string Solid::JoinState(const SavedState& state) {
  if (state.section == nullptr) return state.head;
  const uint64_t n = state.section->size();
  std::string out;
  out.reserve(state.head.size() + n + 16);
  out.append(state.head);
  out.append(*state.section);
  out.append(reinterpret_cast<const char*>(&n), sizeof(n));
  const uint64_t sum = CombinedChecksum(state.head_sum, state.section_sum, n);
  out.append(reinterpret_cast<const char*>(&sum), sizeof(sum));
  return out;
}

SavedState Solid::SaveStateParts() const {
  const Impl& im = *impl_;
  // The head in one buffer sized up front: the header (its payload size
  // patched at the end), the payload up to the material section.
  const models::ElementLayout& l = *im.layout;
  size_t estimate = 64 * 1024 + 8 * static_cast<size_t>(8 * p_.size());
  for (const models::ElementBlock& block : l.blocks) estimate += 8 + 40 * block.size();
  StateWriter w;
  w.out.reserve(estimate);
  w.out.assign(kStateMagic, 8);
  w.Put<uint32_t>(kStateFormatVersion);
  w.Put<uint64_t>(im.fingerprint.first);
  w.Put<uint64_t>(im.fingerprint.second);
  w.Put<uint64_t>(0);  // the payload size, patched below
  w.Put<double>(time_);
  w.Put<int64_t>(steps_);
  w.Put<int64_t>(rollbacks_);
  w.Put<int32_t>(im.substeps);
  w.Put<double>(im.omega_max);
  w.Put<double>(im.stable_step);
  w.Put<uint8_t>(im.forces_valid);
  w.Put<double>(im.last_strain_energy);
  w.Put<uint8_t>(im.ledger_rebase);
  w.Put<double>(im.ledger.work);
  w.Put<double>(im.ledger.h_min);
  w.Put<double>(im.ledger.peak);
  w.Put<uint8_t>(im.ledger.started);
  w.Matrix(p_);
  w.Matrix(p_prev_);
  if (im.contact.active && im.f.rows() == im.contact.force.rows()) {
    w.Matrix(im.f - im.contact.force);  // contact loads are not state
  } else {
    w.Matrix(im.f);
  }
  w.Put<uint8_t>(im.has_pressure);
  if (im.has_pressure) w.Matrix(im.f_press);
  w.Matrix(im.loads.held_at());
  w.Put<uint8_t>(im.use_implicit);
  if (im.use_implicit) {
    const integrators::BackwardEuler::History& warm = im.implicit.history();
    w.Put<int32_t>(warm.steps);
    w.Matrix(warm.last);
    w.Matrix(warm.before);
  }
  w.Bytes(std::string_view(reinterpret_cast<const char*>(im.omega_fixed.data()),
                           im.omega_fixed.size()));
  w.Put<int64_t>(im.loads.next_id());
  w.Vec(im.loads.gravity());
  w.Put<uint64_t>(im.loads.point_loads().size());
  for (const auto& l : im.loads.point_loads()) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.pressures().size());
  for (const auto& l : im.loads.pressures()) {
    w.Put<int64_t>(l.id);
    w.Bytes(l.msg.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.fixes().size());
  for (const auto& c : im.loads.fixes()) {
    w.Put<int64_t>(c.id);
    w.Bytes(c.region.SerializeAsString());
  }
  w.Put<uint64_t>(im.loads.drags().size());
  for (const auto& d : im.loads.drags()) {
    w.Put<int64_t>(d.id);
    w.Put<uint8_t>(d.curve);
    w.Bytes(d.curve ? d.shape.SerializeAsString() : d.drag.SerializeAsString());
  }
  // Version 6: the environment's contacts (empty without one).
  w.Bytes(im.environment != nullptr ? im.environment->SaveState() : std::string());
  // And clay's flow laws, plastic offsets and strains (empty without).
  w.Bytes(im.plasticity != nullptr ? im.plasticity->SaveState() : std::string());
  // Element frames (warm starts).
  const models::InternalForceModel::Frames& frames = im.model->frames();
  for (const auto& f : frames) {
    w.Doubles(reinterpret_cast<const double*>(f.data()), 4 * f.size());
  }
  // The material section (CombinedChecksum), made once per material.
  SavedState saved;
  {
    std::lock_guard<std::mutex> lock(im.section_mu);
    if (im.section_epoch != im.material_epoch || im.section_bytes == nullptr) {
      StateWriter m;
      m.Put<uint64_t>(l.materials.size());
      for (const auto& array : l.materials) {
        m.Doubles(reinterpret_cast<const double*>(array.data()), 4 * array.size());
      }
      for (const models::ElementBlock& block : l.blocks) {
        m.Put<uint64_t>(block.size());
        for (int32_t e = 0; e < block.size(); ++e) m.Put<int32_t>(block.groups[block.group[e]].material);
      }
      im.section_sum = WordChecksum(m.out);
      im.section_bytes = std::make_shared<const std::string>(std::move(m.out));
      im.section_epoch = im.material_epoch;
    }
    saved.section = im.section_bytes;
    saved.section_sum = im.section_sum;
  }
  std::string& out = w.out;
  // The payload: what is here, the section and its length.
  const uint64_t payload = out.size() - kHeaderBytes + saved.section->size() + 8;
  std::memcpy(out.data() + kHeaderBytes - 8, &payload, sizeof(payload));
  saved.head_sum = WordChecksum(out);
  saved.head = std::move(out);
  return saved;
}

absl::Status Solid::RestoreState(std::string_view bytes) { return Restore(bytes, nullptr); }

absl::Status Solid::RestoreStateAtClock(std::string_view bytes, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Restore(bytes, &clock);
}

namespace {

// A saved state's loads and constraints (its gravity aside), validated and
// located again on `im`'s solid (points its current loads have are not
// searched for again). A fault is left in `r`.
LoadSet::Contents ReadLoads(StateReader& r, const Solid::Impl& im, int64_t next_id) {
  LoadSet::Contents out;
  out.next_id = next_id;
  const LoadSet::KnownPoints known = im.loads.CurrentPoints();
  const bool snap = im.settings.snap_forces_to_quadrature();
  int64_t last_id = 0;
  auto check_id = [&](int64_t id, const char* what) {
    if (r.ok() && (id <= last_id || id >= next_id)) {
      r.Fail(absl::StrCat(what, " id ", id, " out of order or not below the next id ", next_id));
    }
    last_id = std::max(last_id, id);
  };
  std::vector<LoadSet::PointLoad>& point_loads = out.point_loads;
  const int64_t n_forces = r.Count("point forces", next_id);
  for (int64_t k = 0; k < n_forces && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("point force id");
    check_id(id, "point force");
    PointForce msg;
    if (!msg.ParseFromString(r.Bytes("point force")) && r.ok()) r.Fail("point force: bad message");
    if (!r.ok()) break;
    const auto was = known.forces.find(LoadSet::KnownPoints::KeyOf(V(msg.position())));
    absl::StatusOr<MaterialLocation> at =
        was != known.forces.end() ? absl::StatusOr<MaterialLocation>(was->second.first)
                                  : im.Locate(V(msg.position()), snap);
    if (!scene::ValidatePointForce(msg, "point_force").ok() || !at.ok()) {
      r.Fail(absl::StrCat("point force ", id, " is invalid for this solid"));
      break;
    }
    // The control row here, off the loop, unless the solid has it.
    std::shared_ptr<const LoadSet::ControlWeights> row =
        was != known.forces.end() && was->second.second != nullptr
            ? was->second.second
            : std::make_shared<const LoadSet::ControlWeights>(im.ControlRowAt(*at));
    point_loads.push_back({id, std::move(msg), *at, std::move(row)});
  }
  last_id = 0;
  std::vector<LoadSet::PressureLoad>& pressures = out.pressures;
  const int64_t n_pressures = r.Count("pressures", next_id);
  for (int64_t k = 0; k < n_pressures && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("pressure id");
    check_id(id, "pressure");
    Pressure msg;
    if (!msg.ParseFromString(r.Bytes("pressure")) && r.ok()) r.Fail("pressure: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> quads;
    if (scene::ValidatePressure(msg, "pressure").ok() &&
        im.CheckControlCells(msg.region(), "pressure.region").ok()) {
      quads = im.SelectQuads(msg.region());
    }
    if (quads.empty()) {
      r.Fail(absl::StrCat("pressure ", id, " is invalid for this solid"));
      break;
    }
    pressures.push_back({id, std::move(msg), std::move(quads)});
  }
  last_id = 0;
  std::vector<LoadSet::FixConstraint>& fixes = out.fixes;
  const int64_t n_fixes = r.Count("fixed regions", next_id);
  for (int64_t k = 0; k < n_fixes && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("fixed region id");
    check_id(id, "fixed region");
    Region region;
    if (!region.ParseFromString(r.Bytes("fixed region")) && r.ok()) r.Fail("fixed region: bad message");
    if (!r.ok()) break;
    std::vector<int32_t> points;
    if (scene::ValidateValues(region, "region").ok() && scene::ValidateRegion(region, "region").ok() &&
        im.CheckControlCells(region, "region").ok()) {
      points = im.SelectControlPoints(region);
    }
    if (points.empty()) {
      r.Fail(absl::StrCat("fixed region ", id, " is invalid for this solid"));
      break;
    }
    fixes.push_back({id, std::move(region), std::move(points)});
  }
  last_id = 0;
  std::vector<LoadSet::DragLoad>& drags = out.drags;
  const int64_t n_drags = r.Count("drags", next_id);
  for (int64_t k = 0; k < n_drags && r.ok(); ++k) {
    const int64_t id = r.Get<int64_t>("drag id");
    check_id(id, "drag");
    const bool curve = r.Get<uint8_t>("drag kind") != 0;
    const std::string bytes = r.Bytes("drag");
    if (!r.ok()) break;
    absl::StatusOr<LoadSet::DragLoad> load = absl::InvalidArgumentError("bad message");
    if (curve) {
      CurveDrag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeCurve(msg, &known);
    } else {
      Drag msg;
      if (msg.ParseFromString(bytes)) load = im.MakeDrag(msg, &known);
    }
    if (!load.ok()) {
      r.Fail(absl::StrCat("drag ", id, " is invalid for this solid: ", load.status().message()));
      break;
    }
    load->id = id;
    drags.push_back(*std::move(load));
  }
  return out;
}

}  // namespace

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareStateView(
    std::string_view bytes) const {
  static_assert(sizeof(models::MaterialPoint) == 4 * sizeof(double));
  const Impl& im = *impl_;
  const int64_t nc = p_.rows();
  if (bytes.size() < kHeaderBytes + 8 || std::memcmp(bytes.data(), kStateMagic, 8) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "solid state: not a dynsolid solid state (", bytes.size(),
        " bytes; it must start with \"DSOLIDST\")"));
  }
  StateReader header(bytes.substr(8, kHeaderBytes - 8));
  const uint32_t version = header.Get<uint32_t>("version");
  const uint64_t fp1 = header.Get<uint64_t>("fingerprint");
  const uint64_t fp2 = header.Get<uint64_t>("fingerprint");
  const uint64_t payload_size = header.Get<uint64_t>("payload size");
  // Version 3 differs from 4 only in its checksum, 4 from 5 in the place
  // of the material section and the checksum: still read.
  if (version != kStateFormatVersion && version != 3 && version != 4 && version != 5) {
    return absl::InvalidArgumentError(absl::StrCat("solid state: format version ", version,
                                                   "; this build reads versions 3 to ",
                                                   kStateFormatVersion));
  }
  uint64_t stored_sum;
  std::memcpy(&stored_sum, bytes.data() + bytes.size() - 8, 8);
  bool sum_ok = payload_size == bytes.size() - kHeaderBytes - 8;
  size_t section_at = 0, section_bytes = 0;
  if (sum_ok && version >= 5) {
    uint64_t n = 0;
    sum_ok = payload_size >= 8;
    if (sum_ok) std::memcpy(&n, bytes.data() + bytes.size() - 16, 8);
    sum_ok = sum_ok && n <= payload_size - 8;
    if (sum_ok) {
      section_bytes = n;
      section_at = bytes.size() - 16 - section_bytes;
      sum_ok = CombinedChecksum(WordChecksum(bytes.substr(0, section_at)),
                                WordChecksum(bytes.substr(section_at, section_bytes)),
                                section_bytes) == stored_sum;
    }
  } else if (sum_ok) {
    sum_ok = Checksum(version, bytes.substr(0, bytes.size() - 8)) == stored_sum;
  }
  if (!sum_ok) {
    return absl::DataLossError(absl::StrCat("solid state: checksum mismatch over ", bytes.size(),
                                            " bytes: the state is corrupt or truncated"));
  }
  if (fp1 != im.fingerprint.first || fp2 != im.fingerprint.second) {
    return absl::InvalidArgumentError(
        "solid state: saved from a different scene or discretization (fingerprint mismatch); "
        "restore into a solid created from the same scene and levels");
  }

  // Parse and check everything before changing anything.
  StateReader r(bytes.substr(kHeaderBytes, payload_size));
  const double time = r.Get<double>("time");
  const int64_t steps = r.Get<int64_t>("steps");
  const int64_t rollbacks = r.Get<int64_t>("rollbacks");
  const int32_t substeps = r.Get<int32_t>("substeps");
  const double omega = r.Get<double>("omega_max");
  const double stable = r.Get<double>("stable_step");
  const bool forces_valid = r.Get<uint8_t>("forces_valid") != 0;
  const double strain = r.Get<double>("strain energy");
  const bool rebase = r.Get<uint8_t>("ledger rebase") != 0;
  Impl::Ledger ledger;
  ledger.work = r.Get<double>("ledger");
  ledger.h_min = r.Get<double>("ledger");
  ledger.peak = r.Get<double>("ledger");
  ledger.started = r.Get<uint8_t>("ledger") != 0;
  Points p = r.Matrix("p", nc), p_prev = r.Matrix("p_prev", nc), f = r.Matrix("forces", nc);
  const bool saved_pressure = r.Get<uint8_t>("pressure flag") != 0;
  Points f_press;
  if (saved_pressure) f_press = r.Matrix("pressure forces", nc);
  Points hold = r.Matrix("held positions", nc);
  const bool saved_implicit = r.Get<uint8_t>("implicit flag") != 0;
  if (r.ok() && saved_implicit != im.use_implicit) {
    r.Fail(absl::StrCat("saved with ", saved_implicit ? "backward Euler" : "central difference",
                        ", this solid steps with the other integrator"));
  }
  integrators::BackwardEuler::History warm;
  if (saved_implicit) {
    warm.steps = r.Get<int32_t>("backward Euler warm start");
    warm.last = r.Matrix("backward Euler warm start", nc);
    warm.before = r.Matrix("backward Euler warm start", nc);
    if (r.ok() && (warm.steps < 0 || warm.steps > 2)) {
      r.Fail(absl::StrCat("backward Euler warm start over ", warm.steps, " steps (0 to 2)"));
    }
  }
  const std::string omega_fixed_bytes = r.Bytes("stable-step fixed set");
  if (r.ok() && static_cast<int64_t>(omega_fixed_bytes.size()) != nc) {
    r.Fail(absl::StrCat("stable-step fixed set: ", omega_fixed_bytes.size(), " entries, expected ",
                        nc));
  }
  const int64_t next_id = r.Get<int64_t>("next id");
  const Eigen::Vector3d gravity = r.Vec("gravity");
  if (r.ok() && (substeps < 1 || substeps > std::max(1, im.settings.max_substeps()))) {
    r.Fail(absl::StrCat("substeps ", substeps, " out of range"));
  }
  RETURN_IF_ERROR(r.status());

  // Loads and constraints: parsed, validated and located again.
  LoadSet::Contents loads = ReadLoads(r, im, next_id);
  RETURN_IF_ERROR(r.status());
  loads.gravity = gravity;
  LoadSet load_set(std::move(loads), std::move(hold));
  if (r.ok() && saved_pressure != (!(load_set.pressures().empty() && load_set.drags().empty()) ||
                                    im.environment != nullptr)) {
    r.Fail("follower forces without pressures, drags or an environment");
  }
  // Version 6: the environment's contacts and clay's state.
  std::vector<contact::ObstacleContact::Touch> touches;
  std::optional<material::Plasticity::State> plastic;
  if (version >= 6 && r.ok()) {
    const std::string env = r.Bytes("environment");
    const std::string clay = r.Bytes("plasticity");
    if (r.ok()) {
      if (absl::Status st = im.ParseParts(env, clay, touches, plastic); !st.ok()) {
        r.Fail(std::string(st.message()));
      }
    }
  }
  RETURN_IF_ERROR(r.status());

  // Material samples and element frames (version 5: frames first, then
  // the material section and its length).
  const models::ElementLayout& cur = *im.layout;
  int64_t max_arrays = 0;
  for (const models::ElementBlock& block : cur.blocks) max_arrays += block.size();
  int64_t n_arrays = 0;
  std::vector<std::vector<models::MaterialPoint>> arrays;
  std::array<std::vector<int32_t>, 3> element_array;
  auto read_materials = [&] {
    n_arrays = r.Count("material arrays", max_arrays);
    arrays.resize(r.ok() ? n_arrays : 0);
    for (int64_t k = 0; k < n_arrays && r.ok(); ++k) {
      const std::vector<double> v = r.Doubles("material array");
      if (!r.ok()) break;
      if (v.size() % 4 != 0) {
        r.Fail("material array: not whole samples");
        break;
      }
      arrays[k].resize(v.size() / 4);
      if (!v.empty()) {
        std::memcpy(static_cast<void*>(arrays[k].data()), v.data(), v.size() * sizeof(double));
      }
    }
    for (int kind = 0; kind < fem::kElementKinds && r.ok(); ++kind) {
      const models::ElementBlock& block = cur.blocks[kind];
      const int64_t count = r.Count("elements", max_arrays);
      if (r.ok() && count != block.size()) {
        r.Fail(absl::StrCat("material of kind ", kind, ": ", count, " elements, the solid has ",
                            block.size()));
      }
      element_array[kind].resize(r.ok() ? count : 0);
      for (int64_t e = 0; e < count && r.ok(); ++e) {
        const int32_t a = r.Get<int32_t>("element material");
        if (r.ok() && (a < 0 || a >= n_arrays ||
                       static_cast<int>(arrays[a].size()) != cur.tables[kind].points)) {
          r.Fail(absl::StrCat("element ", e, " of kind ", kind, ": bad material array ", a));
        }
        element_array[kind][e] = a;
      }
    }
  };
  models::InternalForceModel::Frames frames;
  auto read_frames = [&] {
    for (int kind = 0; kind < fem::kElementKinds && r.ok(); ++kind) {
      const std::vector<double> v = r.Doubles("frames", 4 * int64_t{cur.blocks[kind].size()});
      if (!r.ok()) break;
      frames[kind].resize(cur.blocks[kind].size());
      if (!v.empty()) {
        std::memcpy(static_cast<void*>(frames[kind].data()), v.data(), v.size() * sizeof(double));
      }
    }
  };
  if (version >= 5) {
    read_frames();
    if (r.ok() && kHeaderBytes + r.pos() != section_at) {
      r.Fail(absl::StrCat("the material section starts at byte ", section_at - kHeaderBytes,
                          ", the frames end at ", r.pos()));
    }
    read_materials();
    if (r.ok() && r.Get<uint64_t>("material section length") != section_bytes) {
      r.Fail("material section length");
    }
  } else {
    read_materials();
    read_frames();
  }
  if (r.ok() && !r.at_end()) r.Fail(absl::StrCat("unexpected bytes after byte ", r.pos()));
  RETURN_IF_ERROR(r.status());

  // The material: rebuilt only when it differs from the current one, and
  // taken back when it is the one the current one replaced.
  auto material_is = [&](const models::ElementLayout& l) {
    bool same = static_cast<size_t>(n_arrays) == l.materials.size();
    for (int64_t k = 0; same && k < n_arrays; ++k) {
      same = arrays[k].size() == l.materials[k].size() &&
             std::memcmp(arrays[k].data(), l.materials[k].data(),
                         arrays[k].size() * sizeof(models::MaterialPoint)) == 0;
    }
    for (int kind = 0; kind < fem::kElementKinds && same; ++kind) {
      const models::ElementBlock& block = l.blocks[kind];
      same = static_cast<int64_t>(element_array[kind].size()) == block.size();
      for (int32_t e = 0; e < block.size() && same; ++e) {
        same = element_array[kind][e] == block.groups[block.group[e]].material;
      }
    }
    return same;
  };
  const bool same_material = material_is(cur);
  std::optional<MaterialBuild> build;
  Eigen::SparseMatrix<double> k0;
  std::shared_ptr<const CellPartials> k0_cells;
  std::unique_ptr<WorkerPool> own_pool;
  bool taken_back = false;
  if (!same_material) {
    if (std::optional<Impl::RetiredMaterial> r = im.TakeRetired(material_is)) {
      build = std::move(r->build);
      k0 = std::move(r->k0);
      k0_cells = std::move(r->k0_cells);
      taken_back = true;
    }
  }
  if (!same_material && !taken_back) {
    auto layout = std::make_unique<models::ElementLayout>(models::RelayoutMaterials(
        cur, im.rest_nodes, [&](int kind, int32_t e) { return &arrays[element_array[kind][e]]; }));
    own_pool = std::make_unique<WorkerPool>(1);
    ASSIGN_OR_RETURN(build, im.BuildMaterial(std::move(layout), /*reuse=*/true, own_pool.get()));
    if (im.use_implicit) {
      k0 = im.StiffnessMatrix(*build->layout, *build->corotational, *own_pool, &k0_cells,
                              build->k_cells.get());
    }
  }

  // Backward Euler's Setup for the restored fixed set, sub-steps, mass and
  // K0 (made here, off the loop when a server prepares an undo).
  std::optional<integrators::BackwardEuler::Prepared> implicit_setup;
  if (im.use_implicit) {
    std::vector<uint8_t> fixed = load_set.FixedFlags();
    const SparseMatrix& mt = build ? build->mt : im.mt;
    const bool damped = build ? build->has_damping : im.has_damping;
    const SparseMatrix& dt = build ? build->dt : im.dt;
    if (build) build->corotational->SetSinglePrecisionLinearized(im.SinglePrecisionLinearized());
    implicit_setup = integrators::BackwardEuler::Prepare(mt, damped ? &dt : nullptr, h_ / substeps,
                                                         std::move(fixed), build ? &k0 : &im.k0);
  }

  auto out = std::make_shared<PreparedState>();
  out->material_epoch = im.material_epoch;
  out->taken_back = taken_back;
  out->time = time;
  out->steps = steps;
  out->rollbacks = rollbacks;
  out->substeps = substeps;
  out->omega = omega;
  out->stable = stable;
  out->forces_valid = forces_valid;
  out->strain = strain;
  out->rebase = rebase;
  out->ledger = ledger;
  out->p = std::move(p);
  out->p_prev = std::move(p_prev);
  out->f = std::move(f);
  out->f_press = std::move(f_press);
  out->warm = std::move(warm);
  out->omega_fixed_bytes = omega_fixed_bytes;
  out->loads = std::move(load_set);
  out->touches = std::move(touches);
  out->plastic = std::move(plastic);
  out->frames = std::move(frames);
  out->build = std::move(build);
  out->k0 = std::move(k0);
  out->k0_cells = std::move(k0_cells);
  out->implicit_setup = std::move(implicit_setup);
  out->pool = std::move(own_pool);
  return out;
}

absl::StatusOr<std::shared_ptr<Solid::PreparedState>> Solid::PrepareState(
    std::string bytes) const {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> out, PrepareStateView(bytes));
  out->bytes = std::move(bytes);
  return out;
}

absl::Status Solid::Restore(std::string_view bytes, const std::pair<double, int64_t>* clock) {
  ASSIGN_OR_RETURN(std::shared_ptr<PreparedState> state, PrepareStateView(bytes));
  return Install(*state, clock);
}

absl::Status Solid::RestorePreparedAtClock(PreparedState& state, double time, int64_t steps) {
  const std::pair<double, int64_t> clock{time, steps};
  return Install(state, &clock);
}

absl::Status Solid::Install(PreparedState& prepared, const std::pair<double, int64_t>* clock) {
  Impl& im = *impl_;
  std::shared_ptr<PreparedState> again;
  PreparedState* ps = &prepared;
  if (prepared.material_epoch != im.material_epoch || prepared.used) {
    // Prepared against a material that has changed since: again, now.
    if (prepared.bytes.empty()) {
      return absl::InternalError("solid state: prepared for another material, bytes not kept");
    }
    ASSIGN_OR_RETURN(again, PrepareStateView(prepared.bytes));
    ps = again.get();
  }
  PreparedState& s = *ps;
  s.used = true;
  // Nothing can fail from here on.
  if (s.build) {
    s.build->model->set_pool(*im.pool);
    im.InstallMaterial(*std::move(s.build));
    if (im.use_implicit) {
      im.k0 = std::move(s.k0);
      im.k0_cells = std::move(s.k0_cells);
    }
    total_mass_ = SumOfValues(im.mt);
    ReportMaterial();
    if (s.taken_back) ++report_.materials_taken_back;
  }
  im.model->set_frames(s.frames);
  im.loads = std::move(s.loads);
  im.InstallParts(std::move(s.touches), std::move(s.plastic));
  im.RebuildConstantLoads();
  im.RebuildPressure();
  if (im.has_pressure) im.f_press = std::move(s.f_press);
  im.omega_fixed.assign(s.omega_fixed_bytes.begin(), s.omega_fixed_bytes.end());
  im.omega_max = s.omega;
  im.stable_step = s.stable;
  im.fixed = im.loads.FixedFlags();
  im.SetSubsteps(s.substeps, h_, &s.implicit_setup);
  if (im.use_implicit) im.implicit.set_history(std::move(s.warm));  // checked above
  p_ = std::move(s.p);
  p_prev_ = std::move(s.p_prev);
  im.f = std::move(s.f);
  im.forces_valid = s.forces_valid;
  im.ClearContact();  // the restored `f` carries no contact load
  ++im.contact.epoch;      // and its fixed set or material may differ
  im.loads_changed = true;  // not saved: recomputing the loads changes no bit
  im.last_strain_energy = s.strain;
  im.ledger = s.ledger;
  im.ledger_rebase = s.rebase;
  time_ = clock != nullptr ? clock->first : s.time;
  steps_ = clock != nullptr ? clock->second : s.steps;
  rollbacks_ = s.rollbacks;
  report_.substeps = s.substeps;
  report_.omega_max = s.omega;
  report_.stable_step = s.stable;
  report_.point_forces = static_cast<int32_t>(im.loads.point_loads().size());
  report_.gravity = im.loads.has_gravity();
  report_.fixed_control_points =
      static_cast<int32_t>(std::count(im.fixed.begin(), im.fixed.end(), 1));
  last_step_ = StepStats();
  return absl::OkStatus();
}

}  // namespace dynsolid::solid
