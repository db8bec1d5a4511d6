#include "kinema/forces.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "forces/force_terms.hpp"
#include "core/fnv.hpp"
#include "kinema/error.hpp"

namespace kinema {

std::string term_name(const LocalTerm& term) {
  return visit_term(term, [](const auto&, auto info) { return std::string(info.name); });
}

bool acts_on_rigid_bodies_only(const LocalTerm& term) {
  return visit_term(term, [](const auto&, auto info) { return info.kind == TermKind::rotational; });
}

namespace {

// Every parameter in its range: vectors finite, numbers finite and >= 0.
template <class Term, class Info>
void validate(const Term& t, Info info) {
  for_each_field(info, [&](const auto& field) {
    const auto& value = t.*field.member;
    if constexpr (std::decay_t<decltype(field)>::is_vector) {
      if (!(std::isfinite(value[0]) && std::isfinite(value[1]) && std::isfinite(value[2]))) {
        throw Error(std::string(info.name) + "." + field.key + ": must be finite");
      }
    } else if (!(std::isfinite(value) && value >= 0)) {
      throw Error(std::string(info.name) + "." + field.key + ": must be finite and >= 0");
    }
  });
}

void check_number(double value, const std::string& what) {
  if (!(std::isfinite(value) && value >= 0)) throw Error(what + ": must be finite and >= 0");
}

std::string pair_name(const std::string& what, std::size_t k) {
  return what + "[" + std::to_string(k) + "]";
}

void check_pair(const SpringPair& p, const std::string& name) {
  for (auto [key, index] : {std::pair{".i", p.i}, std::pair{".j", p.j}}) {
    if (index >= kMaxSpringBodies) {
      throw Error(name + key + ": body " + std::to_string(index) + " is past the largest index " +
                  std::to_string(kMaxSpringBodies - 1));
    }
  }
  if (p.i == p.j) throw Error(name + ": joins body " + std::to_string(p.i) + " to itself");
  check_number(p.rest, name + ".rest");
  check_number(p.k, name + ".k");
  check_number(p.damping, name + ".damping");
}

// The first pair that repeats an earlier one (either order).
void check_repeats(std::span<const SpringPair> pairs, const std::string& what) {
  struct Key {
    std::uint32_t lo, hi;
    std::size_t index;
  };
  std::vector<Key> keys(pairs.size());
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    keys[k] = {std::min(pairs[k].i, pairs[k].j), std::max(pairs[k].i, pairs[k].j), k};
  }
  auto order = [](const Key& a, const Key& b) {
    return std::tie(a.lo, a.hi, a.index) < std::tie(b.lo, b.hi, b.index);
  };
  std::sort(keys.begin(), keys.end(), order);
  for (std::size_t k = 1; k < keys.size(); ++k) {
    if (keys[k].lo != keys[k - 1].lo || keys[k].hi != keys[k - 1].hi) continue;
    throw Error(pair_name(what, keys[k].index) + ": repeats " +
                pair_name(what, keys[k - 1].index) + " (bodies " +
                std::to_string(keys[k].lo) + " and " + std::to_string(keys[k].hi) + ")");
  }
}

void check_degrees(std::span<const SpringPair> pairs, const std::string& what) {
  std::vector<std::uint32_t> ends;
  ends.reserve(2 * pairs.size());
  for (const SpringPair& p : pairs) ends.push_back(p.i), ends.push_back(p.j);
  std::sort(ends.begin(), ends.end());
  for (std::size_t a = 0; a < ends.size();) {
    std::size_t b = a;
    while (b < ends.size() && ends[b] == ends[a]) ++b;
    if (b - a > kMaxSpringsPerBody) {
      throw Error(what + ": body " + std::to_string(ends[a]) + " has " + std::to_string(b - a) +
                  " springs, more than " + std::to_string(kMaxSpringsPerBody));
    }
    a = b;
  }
}

}  // namespace

void check_springs(std::span<const SpringPair> pairs, const std::string& what) {
  if (pairs.size() >= kMaxSpringPairs) throw Error(what + ": 2^31 pairs or more");
  // check_pair's tests without its names (millions of pairs): the names only for a bad one.
  const auto in_range = [](double x) { return std::isfinite(x) && x >= 0; };
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    const SpringPair& p = pairs[k];
    const bool ok = p.i < kMaxSpringBodies && p.j < kMaxSpringBodies && p.i != p.j && in_range(p.rest) &&
                    in_range(p.k) && in_range(p.damping);
    if (!ok) check_pair(p, pair_name(what, k));
  }
  check_repeats(pairs, what);
  check_degrees(pairs, what);
}

void check_body_springs(std::span<const BodySpring> springs, const std::string& what) {
  if (springs.size() >= kMaxSpringPairs) throw Error(what + ": 2^31 springs or more");
  std::vector<SpringPair> pairs(springs.size());
  for (std::size_t k = 0; k < springs.size(); ++k) {
    const BodySpring& s = springs[k];
    pairs[k] = {s.i, s.j, s.rest, s.k, s.damping};
    check_pair(pairs[k], pair_name(what, k));
    for (auto [key, point] : {std::pair{".point_i", &s.point_i}, std::pair{".point_j", &s.point_j}}) {
      if (!std::all_of(point->begin(), point->end(), [](double x) { return std::isfinite(x); })) {
        throw Error(pair_name(what, k) + key + ": must be finite");
      }
    }
  }
  check_degrees(pairs, what);  // two bodies may share several springs (at other points)
}

void check_nbody(const NBody& term, const std::string& what) {
  check_number(term.G, what + ".G");
  check_number(term.softening, what + ".softening");
}

template <class T>
ForceModel<T>& ForceModel<T>::add(const LocalTerm& term) {
  visit_term(term, [&](const auto& t, auto info) {
    validate(t, info);
    if constexpr (decltype(info)::max_count > 0) {
      const auto same = [&](const LocalTerm& other) { return other.index() == term.index(); };
      if (std::count_if(local_.begin(), local_.end(), same) == info.max_count) {
        throw Error(std::string(info.name) + ": at most " + std::to_string(info.max_count) +
                    " per model");
      }
    }
  });
  local_.push_back(term);
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(ForceCallback<T> callback) {
  if (!callback) throw Error("callback force: empty function");
  callbacks_.push_back(std::move(callback));
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(RigidCallback<T> callback) {
  if (!callback) throw Error("rigid callback force: empty function");
  rigid_callbacks_.push_back(std::move(callback));
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(std::shared_ptr<const CoupledTerm<T>> term) {
  if (!term) throw Error("coupled force: null term");
  coupled_.push_back(std::move(term));
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(const NBody& term) {
  check_nbody(term, "nbody");
  if (nbody_) throw Error("nbody: at most 1 per model");
  nbody_ = term;
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(const Springs& term) {
  std::vector<SpringPair> joined = springs_;
  joined.insert(joined.end(), term.pairs.begin(), term.pairs.end());
  check_springs(joined, "springs.pairs");
  springs_ = std::move(joined);
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(Springs&& term) {
  if (!springs_.empty()) return add(static_cast<const Springs&>(term));
  check_springs(term.pairs, "springs.pairs");
  springs_ = std::move(term.pairs);
  return *this;
}

template <class T>
ForceModel<T>& ForceModel<T>::add(const BodySprings& term) {
  std::vector<BodySpring> joined = body_springs_;
  joined.insert(joined.end(), term.springs.begin(), term.springs.end());
  check_body_springs(joined, "body_springs");
  body_springs_ = std::move(joined);
  return *this;
}

namespace {

void add_term(Fnv& fnv, const LocalTerm& term) {
  fnv.add(std::uint64_t(term.index()));
  visit_term(term, [&](const auto& t, auto info) {
    for_each_field(info, [&](const auto& field) { fnv.add(t.*field.member); });
  });
}

}  // namespace

template <class T>
std::uint64_t ForceModel<T>::fingerprint() const {
  Fnv fnv;
  fnv.add(std::uint64_t(local_.size()));
  for (const LocalTerm& term : local_) add_term(fnv, term);
  for (const std::size_t count : {callbacks_.size(), rigid_callbacks_.size(), coupled_.size()}) fnv.add(std::uint64_t(count));
  fnv.add(bool(nbody_));
  if (nbody_) fnv.add(nbody_->G), fnv.add(nbody_->softening);
  if (nbody_ && nbody_->fast) fnv.add(std::uint64_t(1));  // exact models keep their older value
  fnv.add(std::uint64_t(springs_.size()));
  for (const SpringPair& p : springs_) fnv.add(p.i), fnv.add(p.j), fnv.add(p.rest), fnv.add(p.k), fnv.add(p.damping);
  if (body_springs_.empty()) return fnv.value();  // the models before body springs keep their value
  fnv.add(std::uint64_t(body_springs_.size()));
  for (const BodySpring& s : body_springs_) {
    fnv.add(s.i), fnv.add(s.j), fnv.add(s.rest), fnv.add(s.k), fnv.add(s.damping);
    for (int d = 0; d < 3; ++d) fnv.add(s.point_i[d]), fnv.add(s.point_j[d]);
  }
  return fnv.value();
}

template class ForceModel<float>;
template class ForceModel<double>;

}  // namespace kinema
