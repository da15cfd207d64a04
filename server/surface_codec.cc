#include "server/surface_codec.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>

#include "absl/strings/str_cat.h"

namespace dynsolid::server {
namespace {

// Code of x on one axis, or -1 when it lies outside the grid.
int64_t Quantize(const Grid& g, int axis, double x) {
  const double q = std::nearbyint((x - g.origin[axis]) / g.step[axis]);
  if (!(q >= 0.0 && q <= static_cast<double>(kMaxCode))) return -1;
  return static_cast<int64_t>(q);
}

uint32_t ZigZag(int32_t d) {
  return d >= 0 ? static_cast<uint32_t>(d) << 1 : (static_cast<uint32_t>(-(d + 1)) << 1) | 1u;
}

int BitWidth(uint32_t v) {
  int b = 0;
  while (v != 0) {
    ++b;
    v >>= 1;
  }
  return b;
}

class BitWriter {
 public:
  explicit BitWriter(std::string* out) : out_(out) {}
  void Put(uint32_t value, int bits) {
    for (int i = 0; i < bits; ++i) {
      if (used_ == 0) out_->push_back('\0');
      if ((value >> i) & 1u) out_->back() = static_cast<char>(out_->back() | (1 << used_));
      used_ = (used_ + 1) & 7;
    }
  }

 private:
  std::string* out_;
  int used_ = 0;
};

// Rice code (service.proto Delta): u = z >> k ones, a zero, k low bits;
// u >= 16 escapes to 16 ones and 17 raw bits.
constexpr int kMaxRiceK = 16;
constexpr uint32_t kRiceEscape = 16;

size_t RiceBits(uint32_t z, int k) {
  const uint32_t u = z >> k;
  return u < kRiceEscape ? u + 1 + k : kRiceEscape + 17;
}

void PutRice(BitWriter& w, uint32_t z, int k) {
  const uint32_t u = z >> k;
  if (u < kRiceEscape) {
    for (uint32_t i = 0; i < u; ++i) w.Put(1, 1);
    w.Put(0, 1);
    w.Put(z & ((1u << k) - 1), k);
  } else {
    for (uint32_t i = 0; i < kRiceEscape; ++i) w.Put(1, 1);
    w.Put(z, 17);
  }
}

void SetVec3(const std::array<double, 3>& a, Vec3* v) {
  v->set_x(a[0]);
  v->set_y(a[1]);
  v->set_z(a[2]);
}

void SetBound(const Grid& g, Vec3* v) {
  v->set_x(g.step[0] / 2);
  v->set_y(g.step[1] / 2);
  v->set_z(g.step[2] / 2);
}

// The bytes of a varint.
size_t VarintSize(uint64_t v) {
  size_t n = 1;
  while (v >= 128) {
    v >>= 7;
    ++n;
  }
  return n;
}

}  // namespace

Grid GridFor(const std::vector<double>& positions) {
  std::array<double, 3> lo{0, 0, 0}, hi{0, 0, 0};
  const size_t n = positions.size() / 3;
  for (int a = 0; a < 3; ++a) {
    if (n > 0) lo[a] = hi[a] = positions[a];
    for (size_t i = 1; i < n; ++i) {
      lo[a] = std::min(lo[a], positions[3 * i + a]);
      hi[a] = std::max(hi[a], positions[3 * i + a]);
    }
  }
  const double largest = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const double floor_margin = largest > 0 ? 1e-3 * largest : 1e-3;
  Grid g;
  for (int a = 0; a < 3; ++a) {
    const double margin = std::max(0.25 * (hi[a] - lo[a]), floor_margin);
    g.origin[a] = lo[a] - margin;
    g.step[a] = (hi[a] - lo[a] + 2 * margin) / kMaxCode;
  }
  return g;
}

bool GridFits(const Grid& g, const std::vector<double>& positions) {
  const size_t n = positions.size() / 3;
  std::array<double, 3> lo{}, hi{};
  for (size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) {
      const double x = positions[3 * i + a];
      if (i == 0 || x < lo[a]) lo[a] = x;
      if (i == 0 || x > hi[a]) hi[a] = x;
      if (Quantize(g, a, x) < 0) return false;
    }
  }
  int big = 0;
  for (int a = 1; a < 3; ++a) {
    if (g.step[a] > g.step[big]) big = a;
  }
  return (hi[big] - lo[big]) >= 0.25 * g.step[big] * kMaxCode;
}

std::shared_ptr<const EncodeCache::Result> EncodeCache::Find(const Key& key) {
  absl::MutexLock lock(&mu_);
  for (auto it = entries_.rbegin(); it != entries_.rend(); ++it) {
    if (it->first == key) {
      ++hits_;
      return it->second;
    }
  }
  ++misses_;
  return nullptr;
}

void EncodeCache::Insert(const Key& key, std::shared_ptr<const Result> result) {
  std::shared_ptr<const Result> dropped;  // freed after the lock
  absl::MutexLock lock(&mu_);
  entries_.emplace_back(key, std::move(result));
  if (entries_.size() > kMaxEntries) {
    dropped = std::move(entries_.front().second);
    entries_.pop_front();
  }
}

std::pair<int64_t, Grid> EncodeCache::KeyGrid(const std::vector<double>& positions) {
  absl::MutexLock lock(&mu_);
  if (grid_id_ == 0 || !GridFits(grid_, positions)) {
    grid_ = GridFor(positions);
    ++grid_id_;
  }
  return {grid_id_, grid_};
}

int64_t EncodeCache::hits() const {
  absl::MutexLock lock(&mu_);
  return hits_;
}
int64_t EncodeCache::misses() const {
  absl::MutexLock lock(&mu_);
  return misses_;
}

void SurfaceEncoder::MakeKeyframe(const SurfaceSnapshot& s, EncodeCache::Result* r) const {
  const SurfaceTopology& topo = *s.topology;
  const size_t n = static_cast<size_t>(topo.vertex_count);
  if (cache_ != nullptr) {
    std::tie(r->grid_id, r->grid) = cache_->KeyGrid(s.positions);
  } else {
    r->grid_id = grid_id_ + 1;
    r->grid = GridFor(s.positions);
  }
  auto codes = std::make_shared<std::vector<uint16_t>>(3 * n);
  for (size_t i = 0; i < 3 * n; ++i) {
    const int64_t q = Quantize(r->grid, static_cast<int>(i % 3), s.positions[i]);
    (*codes)[i] = static_cast<uint16_t>(std::clamp<int64_t>(q, 0, kMaxCode));
  }
  r->keyframe = true;
  r->frame.clear_delta();
  Keyframe* k = r->frame.mutable_keyframe();
  k->set_topology_version(topo.version);
  k->set_vertex_count(topo.vertex_count);
  k->mutable_quads()->Assign(topo.quads.begin(), topo.quads.end());
  k->mutable_nodes()->Assign(topo.nodes.begin(), topo.nodes.end());
  SetVec3(r->grid.origin, k->mutable_grid()->mutable_origin());
  SetVec3(r->grid.step, k->mutable_grid()->mutable_step());
  SetBound(r->grid, k->mutable_error_bound());
  std::string* bytes = k->mutable_codes();
  bytes->resize(6 * n);
  for (size_t i = 0; i < 3 * n; ++i) {
    (*bytes)[2 * i] = static_cast<char>((*codes)[i] & 0xff);
    (*bytes)[2 * i + 1] = static_cast<char>((*codes)[i] >> 8);
  }
  SurfaceFields* f = k->mutable_fields();
  if (fields_.displacement) f->mutable_displacement()->Assign(s.displacement.begin(), s.displacement.end());
  if (fields_.strain) f->mutable_strain()->Assign(s.strain.begin(), s.strain.end());
  if (fields_.stiffness) f->mutable_stiffness()->Assign(s.stiffness.begin(), s.stiffness.end());
  if (fields_.mass) f->mutable_mass()->Assign(s.mass.begin(), s.mass.end());
  if (!fields_.any()) k->clear_fields();
  r->codes = std::move(codes);
}

std::shared_ptr<EncodeCache::Result> SurfaceEncoder::Compute(const SurfaceSnapshot& s) const {
  auto r = std::make_shared<EncodeCache::Result>();
  r->frame.set_step(s.step);
  r->frame.set_time(s.time);
  const SurfaceTopology& topo = *s.topology;
  const size_t n = static_cast<size_t>(topo.vertex_count);

  bool key = base_ == nullptr || topo.version != base_->topology->version ||
             (fields_.any() && s.fields_version != base_->fields_version) ||
             codes_ == nullptr || codes_->size() != 3 * n || !GridFits(grid_, s.positions);
  if (!key) {
    const std::vector<uint16_t>& old = *codes_;
    auto codes = std::make_shared<std::vector<uint16_t>>(3 * n);
    for (size_t i = 0; i < 3 * n; ++i) {
      (*codes)[i] = static_cast<uint16_t>(Quantize(grid_, static_cast<int>(i % 3), s.positions[i]));
    }
    const std::vector<uint16_t>& now = *codes;
    const auto moved_at = [&](size_t i) {
      return now[3 * i] != old[3 * i] || now[3 * i + 1] != old[3 * i + 1] ||
             now[3 * i + 2] != old[3 * i + 2];
    };
    // Runs of moved vertices, the largest code difference, Rice costs.
    std::vector<uint32_t> runs;
    uint32_t max_zigzag = 0;
    int32_t moved = 0;
    bool taking = false;
    uint32_t run = 0;
    std::array<std::array<size_t, kMaxRiceK + 1>, 3> cost{};
    for (size_t i = 0; i < n; ++i) {
      const bool m = moved_at(i);
      if (m != taking) {
        runs.push_back(run);
        run = 0;
        taking = m;
      }
      ++run;
      if (!m) continue;
      ++moved;
      for (int a = 0; a < 3; ++a) {
        const uint32_t z = ZigZag(static_cast<int32_t>(now[3 * i + a]) - old[3 * i + a]);
        max_zigzag = std::max(max_zigzag, z);
        for (int k = 0; k <= kMaxRiceK; ++k) cost[a][k] += RiceBits(z, k);
      }
    }
    if (taking) runs.push_back(run);
    if (moved == 0) runs.clear();
    const int bits = std::max(1, BitWidth(max_zigzag));
    std::array<int, 3> rice_k{0, 0, 0};
    size_t rice_bits = 0;
    for (int a = 0; a < 3; ++a) {
      for (int k = 1; k <= kMaxRiceK; ++k) {
        if (cost[a][k] < cost[a][rice_k[a]]) rice_k[a] = k;
      }
      rice_bits += cost[a][rice_k[a]];
    }
    const size_t fixed_bits = static_cast<size_t>(moved) * 3 * bits;
    const bool rice = rice_bits < fixed_bits;
    size_t delta_bytes = ((rice ? rice_bits : fixed_bits) + 7) / 8;
    for (uint32_t x : runs) delta_bytes += VarintSize(x);
    const int field_count = fields_.count();
    delta_bytes += static_cast<size_t>(moved) * 4 * field_count;
    const size_t key_bytes = 6 * n + 4 * n * field_count;
    if (delta_bytes > key_bytes) {
      key = true;  // a stale watcher: a fresh keyframe is smaller
    } else {
      Delta* d = r->frame.mutable_delta();
      d->set_base_step(base_->step);
      d->mutable_runs()->Assign(runs.begin(), runs.end());
      if (rice) {
        d->set_bits(0);
        d->mutable_rice_k()->Add(rice_k.begin(), rice_k.end());
      } else {
        d->set_bits(static_cast<uint32_t>(bits));
      }
      d->set_moved(moved);
      SetBound(grid_, d->mutable_error_bound());
      std::string* packed = d->mutable_packed();
      packed->reserve(delta_bytes);
      BitWriter w(packed);
      SurfaceFields* f = d->mutable_fields();
      for (size_t i = 0; i < n; ++i) {
        if (!moved_at(i)) continue;
        for (int a = 0; a < 3; ++a) {
          const uint32_t z = ZigZag(static_cast<int32_t>(now[3 * i + a]) - old[3 * i + a]);
          if (rice) {
            PutRice(w, z, rice_k[a]);
          } else {
            w.Put(z, bits);
          }
        }
        if (fields_.displacement) f->add_displacement(s.displacement[i]);
        if (fields_.strain) f->add_strain(s.strain[i]);
        if (fields_.stiffness) f->add_stiffness(s.stiffness[i]);
        if (fields_.mass) f->add_mass(s.mass[i]);
      }
      if (!fields_.any()) d->clear_fields();
      r->grid_id = grid_id_;
      r->grid = grid_;
      r->codes = std::move(codes);
    }
  }
  if (key) MakeKeyframe(s, r.get());
  return r;
}

std::shared_ptr<const EncodeCache::Result> SurfaceEncoder::EncodeShared(
    std::shared_ptr<const SurfaceSnapshot> s) {
  const EncodeCache::Key key{s.get(), base_.get(), base_ != nullptr ? grid_id_ : -1,
                             fields_.bits()};
  std::shared_ptr<const EncodeCache::Result> r =
      cache_ != nullptr ? cache_->Find(key) : nullptr;
  if (r == nullptr) {
    std::shared_ptr<EncodeCache::Result> fresh = Compute(*s);
    fresh->bytes = std::make_shared<const std::string>(fresh->frame.SerializeAsString());
    fresh->snapshot = s;
    fresh->base = base_;
    r = fresh;
    if (cache_ != nullptr) cache_->Insert(key, r);
  }
  grid_id_ = r->grid_id;
  grid_ = r->grid;
  codes_ = r->codes;
  base_ = std::move(s);
  return r;
}

bool SurfaceEncoder::Encode(std::shared_ptr<const SurfaceSnapshot> s, Frame* frame) {
  std::shared_ptr<const EncodeCache::Result> r = EncodeShared(std::move(s));
  frame->CopyFrom(r->frame);
  return r->keyframe;
}

std::string FrameTrailer(int64_t skipped, int64_t watcher_id) {
  Frame f;
  f.set_skipped(skipped);
  f.set_watcher_id(watcher_id);
  return f.SerializeAsString();
}

}  // namespace dynsolid::server
