#include "forces/coupled_forces.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <string>

#include "core/text.hpp"
#include "kinema/error.hpp"

namespace kinema {
namespace {

using kernels::kSpringSlice;

// Each body's springs as (other end, pair index), in model order.
struct Adjacency {
  std::vector<std::uint32_t> start;  // bodies + 1
  std::vector<std::uint32_t> other, pair;

  Adjacency(std::span<const SpringPair> pairs, std::size_t bodies) : start(bodies + 1, 0) {
    for (const SpringPair& p : pairs) ++start[p.i + 1], ++start[p.j + 1];
    for (std::size_t b = 0; b < bodies; ++b) start[b + 1] += start[b];
    other.resize(start[bodies]);
    pair.resize(start[bodies]);
    std::vector<std::uint32_t> next(start.begin(), start.end() - 1);
    for (std::uint32_t k = 0; k < pairs.size(); ++k) {
      other[next[pairs[k].i]] = pairs[k].j, pair[next[pairs[k].i]++] = k;
      other[next[pairs[k].j]] = pairs[k].i, pair[next[pairs[k].j]++] = k;
    }
  }
  std::uint32_t degree(std::size_t body) const { return start[body + 1] - start[body]; }
};

// Which spring of its body each lane takes in each entry of a slice: an index into the
// adjacency, or -1 for none. Where the slice's bodies reach few distinct offsets (j - i),
// as in chains and grids, an entry holds one offset: its lanes' other ends are consecutive
// bodies, loaded without a gather. Otherwise entries follow each body's springs in model
// order. Either way the order is fixed here, once.
using SliceLayout = std::vector<std::array<std::int64_t, kSpringSlice>>;

SliceLayout slice_layout(const Adjacency& adjacency, std::size_t slice, std::size_t covered) {
  const std::size_t first = slice * kSpringSlice, last = std::min(covered, first + kSpringSlice);
  std::uint32_t widest = 0;
  std::vector<std::int64_t> offsets;
  for (std::size_t b = first; b < last; ++b) {
    widest = std::max(widest, adjacency.degree(b));
    for (std::uint32_t s = adjacency.start[b]; s < adjacency.start[b + 1]; ++s) {
      offsets.push_back(std::int64_t(adjacency.other[s]) - std::int64_t(b));
    }
  }
  std::sort(offsets.begin(), offsets.end());
  offsets.erase(std::unique(offsets.begin(), offsets.end()), offsets.end());
  const bool by_offset = offsets.size() <= 2 * std::size_t(widest);
  SliceLayout layout(by_offset ? offsets.size() : widest);
  for (auto& entry : layout) entry.fill(-1);
  for (std::size_t b = first; b < last; ++b) {
    for (std::uint32_t s = adjacency.start[b]; s < adjacency.start[b + 1]; ++s) {
      const std::int64_t offset = std::int64_t(adjacency.other[s]) - std::int64_t(b);
      const std::size_t e = by_offset ? std::size_t(std::lower_bound(offsets.begin(), offsets.end(), offset) - offsets.begin())
                                      : s - adjacency.start[b];
      layout[e][b - first] = s;
    }
  }
  return layout;
}

template <class T>
void fill_slice(const Adjacency& adjacency, std::span<const SpringPair> pairs, std::size_t slice,
                const SliceLayout& layout, SpringNetwork<T>& net) {
  const std::size_t first_entry = net.slice_offset[slice];
  for (std::size_t e = 0; e < layout.size(); ++e) {
    for (std::size_t lane = 0; lane < kSpringSlice; ++lane) {
      const std::size_t at = (first_entry + e) * kSpringSlice + lane;
      const std::int64_t slot = layout[e][lane];
      // An empty slot: the body itself (no force), and a rest length of -1 that masks it
      // where the entry loads consecutive bodies.
      net.neighbor[at] = std::int32_t(slot < 0 ? slice * kSpringSlice + lane : adjacency.other[slot]);
      if (slot < 0) {
        net.rest[at] = T(-1);
        continue;
      }
      const SpringPair& p = pairs[adjacency.pair[slot]];
      net.rest[at] = T(p.rest), net.k[at] = T(p.k), net.damping[at] = T(p.damping);
    }
  }
}

// An entry loads its other ends as one vector when every lane with a spring has first +
// lane there, and the 16 bodies from `first` exist; its empty lanes (if any) are masked then,
// so a body loaded for them cannot reach this one. Otherwise the entry is gathered.
template <class T>
void mark_contiguous(const std::vector<SliceLayout>& layouts, SpringNetwork<T>& net) {
  for (std::size_t slice = 0; slice < layouts.size(); ++slice) {
    for (std::size_t e = 0; e < layouts[slice].size(); ++e) {
      const std::size_t entry = net.slice_offset[slice] + e;
      const std::int32_t* lanes = net.neighbor.data() + entry * kSpringSlice;
      std::int64_t first = -1;
      bool run = true, full = true;
      for (std::size_t l = 0; l < kSpringSlice; ++l) {
        if (layouts[slice][e][l] < 0) {
          full = false;
          continue;
        }
        if (first < 0) first = std::int64_t(lanes[l]) - std::int64_t(l);
        run = run && std::int64_t(lanes[l]) - std::int64_t(l) == first;
      }
      run = run && first >= 0 && std::size_t(first) + kSpringSlice <= net.covered;
      net.contiguous[entry] = !run ? -1 : full ? std::int32_t(first) : -std::int32_t(first) - 2;
    }
  }
}

template <class T>
void check_in(double value, const char* what) {
  if (!(std::abs(value) <= double(std::numeric_limits<T>::max()))) {
    throw Error(std::string(what) + ": " + shortest_text(value) + " overflows " + type_name<T>());
  }
}

// The reach and the parameters' range now; the layout once a set shows it has the bodies.
template <class T>
SpringNetwork<T> lower_springs(std::span<const SpringPair> pairs) {
  SpringNetwork<T> net;
  net.pairs = pairs;
  net.covered = network_reach(pairs);
  for (const SpringPair& p : pairs) {
    check_in<T>(p.rest, "springs.rest"), check_in<T>(p.k, "springs.k");
    check_in<T>(p.damping, "springs.damping");
  }
  return net;
}

}  // namespace

template <class T>
void SpringNetwork<T>::lay_out() {
  if (laid_out || pairs.empty()) return;
  SpringNetwork<T>& net = *this;
  const Adjacency adjacency(pairs, net.covered);
  const std::size_t slices = (net.covered + kSpringSlice - 1) / kSpringSlice;
  std::vector<SliceLayout> layouts(slices);
  net.slice_offset.assign(slices + 1, 0);
  for (std::size_t s = 0; s < slices; ++s) {
    layouts[s] = slice_layout(adjacency, s, net.covered);
    net.slice_offset[s + 1] = net.slice_offset[s] + std::uint32_t(layouts[s].size());
  }
  const std::size_t entries = net.slice_offset[slices];
  net.neighbor.resize(entries * kSpringSlice);
  net.contiguous.resize(entries);
  for (auto* a : {&net.rest, &net.k, &net.damping}) a->resize(entries * kSpringSlice);
  for (std::size_t s = 0; s < slices; ++s) fill_slice(adjacency, pairs, s, layouts[s], net);
  mark_contiguous(layouts, net);
  laid_out = true;
}

namespace {

double mass_of(double inv_mass) { return 1.0 / inv_mass; }

}  // namespace

template <class T>
kernels::SpringJob<T> SpringNetwork<T>::job(const T* const x[3], const T* const v[3],
                                            T* const force[3]) const {
  assert(laid_out || pairs.empty());
  return {{x[0], x[1], x[2]}, {v[0], v[1], v[2]}, covered,  slice_offset.data(),
          neighbor.data(),    contiguous.data(),  rest.data(), k.data(),
          damping.data(),     {force[0], force[1], force[2]}};
}

template <class T>
CoupledForces<T> lower_coupled(const ForceModel<T>& forces) {
  CoupledForces<T> out;
  out.nbody = forces.nbody();
  if (out.nbody) {
    check_in<T>(out.nbody->G, "nbody.G");
    check_in<T>(out.nbody->softening * out.nbody->softening, "nbody.softening squared");
    out.eps2 = T(out.nbody->softening) * T(out.nbody->softening);
  }
  out.springs = lower_springs<T>(forces.springs());
  return out;
}

// The bodies with a mass, in order and in double: the same sums as over the set, without a
// test and a division per pair.
struct MassivePoints {
  std::vector<double> x, y, z, m;
  template <class T>
  explicit MassivePoints(const ParticleSet<T>& b) {
    for (std::size_t i = 0; i < b.size(); ++i) {
      if (b.inv_mass()[i] == 0) continue;
      x.push_back(b.px()[i]), y.push_back(b.py()[i]), z.push_back(b.pz()[i]);
      m.push_back(mass_of(b.inv_mass()[i]));
    }
  }
};

// About 10 ms of pairs: the sum polls its stop request this often.
constexpr std::size_t kPairsPerPoll = std::size_t(1) << 23;

template <class T>
double nbody_potential(const ParticleSet<T>& b, const NBody& term, const StopRequest& stop) {
  const MassivePoints p(b);
  const std::size_t n = p.m.size();
  const double eps2 = term.softening * term.softening;
  double u = 0;
  std::size_t pairs_since_poll = 0;
  for (std::size_t i = 0; i < n; ++i) {
    double row = 0;
    for (std::size_t j = i + 1; j < n; ++j) {
      const double dx = p.x[j] - p.x[i], dy = p.y[j] - p.y[i], dz = p.z[j] - p.z[i];
      const double r2 = dx * dx + dy * dy + dz * dz + eps2;
      if (r2 > 0) row += p.m[j] / std::sqrt(r2);
    }
    u -= term.G * p.m[i] * row;
    pairs_since_poll += n - i;
    if (pairs_since_poll < kPairsPerPoll) continue;
    pairs_since_poll = 0;
    if (stop && stop()) throw Stopped();
  }
  return u;
}

void check_springs_reach(std::size_t covered, std::size_t bodies) {
  if (covered <= bodies) return;
  throw Error("springs: a pair joins body " + std::to_string(covered - 1) + ", but the set has " +
              std::to_string(bodies) + " bodies");
}

template <class T>
double spring_potential(const ParticleSet<T>& b, std::span<const SpringPair> pairs) {
  std::size_t covered = 0;
  for (const SpringPair& p : pairs) covered = std::max<std::size_t>(covered, std::max(p.i, p.j) + std::size_t(1));
  check_springs_reach(covered, b.size());
  double u = 0;
  for (const SpringPair& p : pairs) {
    const double dx = double(b.px()[p.j]) - b.px()[p.i], dy = double(b.py()[p.j]) - b.py()[p.i],
                 dz = double(b.pz()[p.j]) - b.pz()[p.i];
    const double stretch = std::sqrt(dx * dx + dy * dy + dz * dz) - p.rest;
    u += 0.5 * p.k * stretch * stretch;
  }
  return u;
}

#define KINEMA_COUPLED(T)                                                               \
  template struct SpringNetwork<T>;                                                     \
  template CoupledForces<T> lower_coupled(const ForceModel<T>&);                        \
  template double nbody_potential(const ParticleSet<T>&, const NBody&, const StopRequest&); \
  template double spring_potential(const ParticleSet<T>&, std::span<const SpringPair>);
KINEMA_COUPLED(float)
KINEMA_COUPLED(double)
#undef KINEMA_COUPLED

}  // namespace kinema
