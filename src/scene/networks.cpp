#include "scene/networks.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <vector>

namespace kinema {
namespace {

using scene_json::Node;

std::uint32_t index_in(const Node& n) {
  const std::uint64_t i = n.count(true);
  if (i >= kMaxSpringBodies) n.fail("expected a body index below 2^30");
  return std::uint32_t(i);
}

SpringPair parse_pair(const Node& n) {
  if (!n.value.is_array() || n.value.size() != 5) n.fail("expected [i, j, rest, k, damping]");
  return {index_in(n.element(0)), index_in(n.element(1)), n.element(2).non_negative(),
          n.element(3).non_negative(), n.element(4).non_negative()};
}

// The parameters a generator's springs and bodies share.
struct Network {
  std::size_t first = 0;  // index of the generator's first body in the scene
  double spacing = 1, k = 0, shear_k = 0, damping = 0, mass = 1;
  Vec3<double> origin{};
};

Network parse_network(const Node& n, std::size_t first) {
  Network net;
  net.first = first;
  net.spacing = n.required("spacing").positive();
  net.k = n.required("k").non_negative();
  net.shear_k = n.has("shear_k") ? n.child("shear_k").non_negative() : net.k;
  if (n.has("damping")) net.damping = n.child("damping").non_negative();
  if (n.has("mass")) net.mass = n.child("mass").positive();
  if (n.has("origin")) net.origin = n.child("origin").vec3();
  return net;
}

std::uint64_t body_count(const Node& n, const char* key) {
  const std::uint64_t count = n.required(key).count(false);
  if (count > kMaxNetworkBodies) n.child(key).fail("expected at most 2^20 bodies");
  return count;
}

// Every generator adds to the scene's particles: their total is bounded too.
void check_room(const Node& n, const Scene& scene, std::uint64_t count) {
  if (scene.particles.size() + count > kMaxNetworkScene) {
    n.fail("the listed particles and the bodies of every generator come to more than 2^22");
  }
}

void pin(const Node& n, std::vector<BodySpec>& bodies, std::size_t first, std::size_t count) {
  if (!n.value.is_array()) n.fail("expected an array of body indices");
  for (std::size_t k = 0; k < n.value.size(); ++k) {
    const Node at = n.element(k);
    const std::uint64_t i = at.count(true);
    if (i >= count) at.fail("expected an index below " + std::to_string(count) + " (the generator's bodies)");
    if (bodies[first + i].kinematic) at.fail("body " + std::to_string(i) + " is pinned twice");  // a typo for another
    bodies[first + i].kinematic = true;
  }
}

void add_spring(Springs& springs, const Network& net, std::size_t a, std::size_t b, double rest, double k) {
  springs.pairs.push_back({std::uint32_t(net.first + a), std::uint32_t(net.first + b), rest, k, net.damping});
}

// count bodies from origin along a unit direction, spacing apart, each joined to the next.
Springs make_chain(const Node& n, Scene& scene) {
  n.expect_object({"count", "spacing", "k", "damping", "mass", "origin", "direction", "pinned"});
  const Network net = parse_network(n, scene.particles.size());
  const std::uint64_t count = body_count(n, "count");
  check_room(n, scene, count);
  Vec3<double> dir{0, -1, 0};
  if (n.has("direction")) {
    dir = n.child("direction").vec3();
    const double length = std::hypot(dir[0], dir[1], dir[2]);
    if (!(length > 0 && std::isfinite(length))) n.child("direction").fail("expected a nonzero direction");
    for (double& d : dir) d /= length;
  }
  Springs springs;
  for (std::uint64_t i = 0; i < count; ++i) {
    BodySpec b;
    for (int d = 0; d < 3; ++d) b.position[d] = net.origin[d] + double(i) * net.spacing * dir[d];
    b.mass = net.mass;
    scene.particles.push_back(b);
    if (i > 0) add_spring(springs, net, i - 1, i, net.spacing, net.k);
  }
  scene.generated_particles.push_back({net.first, std::size_t(count), n.path});
  if (n.has("pinned")) {
    pin(n.child("pinned"), scene.particles, net.first, count);
  } else if (count > 0) {
    scene.particles[net.first].kinematic = true;
  }
  return springs;
}

// rows x columns bodies in the x-z plane (columns along x, rows along z), with structural
// springs to the right and below and shear springs along both diagonals of each cell.
Springs make_grid(const Node& n, Scene& scene) {
  n.expect_object({"rows", "columns", "spacing", "k", "shear_k", "damping", "mass", "origin", "pinned"});
  const Network net = parse_network(n, scene.particles.size());
  const std::uint64_t rows = body_count(n, "rows"), columns = body_count(n, "columns");
  if (rows * columns > kMaxNetworkBodies) n.fail("expected at most 2^20 bodies (rows x columns)");
  check_room(n, scene, rows * columns);
  const double diagonal = net.spacing * std::sqrt(2.0);
  auto at = [&](std::uint64_t r, std::uint64_t c) { return r * columns + c; };
  Springs springs;
  for (std::uint64_t r = 0; r < rows; ++r) {
    for (std::uint64_t c = 0; c < columns; ++c) {
      BodySpec b;
      b.position = {net.origin[0] + double(c) * net.spacing, net.origin[1], net.origin[2] + double(r) * net.spacing};
      b.mass = net.mass;
      scene.particles.push_back(b);
      if (c + 1 < columns) add_spring(springs, net, at(r, c), at(r, c + 1), net.spacing, net.k);
      if (r + 1 < rows) add_spring(springs, net, at(r, c), at(r + 1, c), net.spacing, net.k);
      if (r + 1 < rows && c + 1 < columns) {
        add_spring(springs, net, at(r, c), at(r + 1, c + 1), diagonal, net.shear_k);
        add_spring(springs, net, at(r, c + 1), at(r + 1, c), diagonal, net.shear_k);
      }
    }
  }
  scene.generated_particles.push_back({net.first, std::size_t(rows * columns), n.path});
  if (!n.has("pinned")) return springs;
  const Node pinned = n.child("pinned");
  if (pinned.value.is_string()) {
    if (pinned.string() != "top_corners") pinned.fail("expected \"top_corners\" or an array of body indices");
    scene.particles[net.first].kinematic = scene.particles[net.first + columns - 1].kinematic = true;
  } else {
    pin(pinned, scene.particles, net.first, rows * columns);
  }
  return springs;
}

Springs parse_springs(const Node& n, Scene& scene) {
  int forms = 0;
  for (const char* key : {"pairs", "chain", "grid"}) forms += n.has(key);
  if (forms != 1) n.fail("expected one of 'pairs', 'chain' or 'grid'");
  n.expect_object({"type", "pairs", "chain", "grid"});
  if (n.has("chain")) return make_chain(n.child("chain"), scene);
  if (n.has("grid")) return make_grid(n.child("grid"), scene);
  const Node list = n.child("pairs");
  if (!list.value.is_array()) list.fail("expected an array of [i, j, rest, k, damping]");
  Springs springs;
  springs.pairs.reserve(list.value.size());
  for (std::size_t k = 0; k < list.value.size(); ++k) springs.pairs.push_back(parse_pair(list.element(k)));
  try {
    check_springs(springs.pairs, list.path);
  } catch (const Error& e) {
    throw Error(printable(std::string(n.origin) + ": " + e.what()));
  }
  return springs;
}

// {"type": "body_springs", "springs": [{"i": 0, "j": 1, "point_i": [..], "point_j": [..],
// "rest": .., "k": .., "damping": ..}, ...]}: points default to the centres, rest and damping
// to 0.
void parse_body_springs(const Node& n, Scene& scene) {
  n.expect_object({"type", "springs"});
  const Node list = n.required("springs");
  if (!list.value.is_array()) list.fail("expected an array of springs");
  for (std::size_t k = 0; k < list.value.size(); ++k) {
    const Node e = list.element(k);
    e.expect_object({"i", "j", "point_i", "point_j", "rest", "k", "damping"});
    BodySpring b;
    b.i = index_in(e.required("i")), b.j = index_in(e.required("j"));
    if (e.has("point_i")) b.point_i = e.child("point_i").vec3();
    if (e.has("point_j")) b.point_j = e.child("point_j").vec3();
    if (e.has("rest")) b.rest = e.child("rest").non_negative();
    b.k = e.required("k").non_negative();
    if (e.has("damping")) b.damping = e.child("damping").non_negative();
    if (b.i == b.j) e.fail("joins body " + std::to_string(b.i) + " to itself");
    scene.body_springs.springs.push_back(b);
  }
  try {  // what is left to check: how many springs a body has, over every term so far
    check_body_springs(scene.body_springs.springs, list.path);
  } catch (const Error& e) {
    throw Error(printable(std::string(n.origin) + ": " + e.what()));
  }
}

}  // namespace

bool is_coupled_force(std::string_view type) { return type == "nbody" || type == "springs" || type == "body_springs"; }

void parse_coupled_force(const Node& n, const std::string& type, Scene& scene) {
  if (type == "springs") {
    scene.springs.push_back(parse_springs(n, scene));
    return;
  }
  if (type == "body_springs") return parse_body_springs(n, scene);
  n.expect_object({"type", "G", "softening", "fast"});
  if (scene.nbody) n.fail("at most one nbody term per scene");
  NBody term;
  if (n.has("G")) term.G = n.child("G").non_negative();
  if (n.has("softening")) term.softening = n.child("softening").non_negative();
  if (n.has("fast")) term.fast = n.child("fast").boolean();
  scene.nbody = term;
}

namespace {

// Term t's k-th pair as the file has it: a listed pair's path, or its generator's.
std::string pair_path(const Node& term, std::size_t k) {
  if (term.has("pairs")) return term.child("pairs").element(k).path;
  return term.child(term.has("chain") ? "chain" : "grid").path + " (its spring " + std::to_string(k) + ")";
}

// A pair that repeats one of an earlier springs term (within one term, parse_springs
// refuses it), named as written.
void check_repeats_across(const Scene& scene, std::span<const Node> terms) {
  if (terms.size() < 2) return;
  std::vector<std::array<std::uint64_t, 3>> keys;  // {both bodies, term, pair}: file order within a key
  for (std::size_t t = 0; t < terms.size(); ++t) {
    const auto& pairs = scene.springs[t].pairs;
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const std::uint64_t lo = std::min(pairs[k].i, pairs[k].j), hi = std::max(pairs[k].i, pairs[k].j);
      keys.push_back({lo << 32 | hi, t, k});
    }
  }
  std::sort(keys.begin(), keys.end());
  for (std::size_t n = 1; n < keys.size(); ++n) {
    if (keys[n][0] != keys[n - 1][0]) continue;
    const Node& term = terms[keys[n][1]];
    const std::string bodies = "bodies " + std::to_string(keys[n][0] >> 32) + " and " +
                               std::to_string(keys[n][0] & 0xffffffffu);
    const std::string earlier = pair_path(terms[keys[n - 1][1]], keys[n - 1][2]);
    if (term.has("pairs")) term.child("pairs").element(keys[n][2]).fail("repeats " + earlier + " (" + bodies + ")");
    term.child(term.has("chain") ? "chain" : "grid").fail("its spring between " + bodies + " repeats " + earlier);
  }
}

// The listed position of body i of the kind the springs join, or null for a generated one.
const Vec3<double>* listed_position(const Scene& scene, bool rigid, std::uint32_t i) {
  if (rigid) return i < scene.rigid_bodies.size() ? &scene.rigid_bodies[i].position : nullptr;
  return i < scene.particles.size() ? &scene.particles[i].position : nullptr;
}

// Whether two positions are one point in the scene's precision.
bool same_point(const Vec3<double>& a, const Vec3<double>& b, Precision precision) {
  if (precision != Precision::single) return a == b;
  return float(a[0]) == float(b[0]) && float(a[1]) == float(b[1]) && float(a[2]) == float(b[2]);
}

// A spring of positive rest length whose ends start at one point pushes them apart along no
// direction: its force jumps there from zero to k rest (and the stiffness estimate, from
// finite differences, with it).
void check_coincident_ends(const Scene& scene, bool rigid, const Node& pairs_node, const Springs& springs) {
  for (std::size_t k = 0; k < springs.pairs.size(); ++k) {
    const SpringPair& p = springs.pairs[k];
    const Vec3<double>* a = listed_position(scene, rigid, p.i);
    const Vec3<double>* b = listed_position(scene, rigid, p.j);
    if (!a || !b || !same_point(*a, *b, scene.precision) || !(p.rest > 0 && p.k > 0)) continue;
    char text[224];
    std::snprintf(text, sizeof text,
                  "bodies %u and %u both start at (%g, %g, %g) with rest length %g: the spring has no direction "
                  "to push them apart along (place them apart, or give rest 0)",
                  p.i, p.j, (*a)[0], (*a)[1], (*a)[2], p.rest);
    pairs_node.element(k).fail(text);
  }
}

}  // namespace

std::size_t particle_count(const Scene& scene) {
  const bool generated = scene.generate && !scene.generate->rigid;
  return scene.particles.size() + (generated ? scene.generate->count : 0);
}

std::size_t rigid_count(const Scene& scene) {
  const bool generated = scene.generate && scene.generate->rigid;
  return scene.rigid_bodies.size() + (generated ? scene.generate->count : 0);
}

bool mixed_bodies(const Scene& scene) { return particle_count(scene) > 0 && rigid_count(scene) > 0; }

void check_coupled(const Scene& scene, std::span<const Node> terms, std::span<const Node> body_terms) {
  // Pairs join the bodies of the one kind the scene has.
  const bool rigid = rigid_count(scene) > 0;
  const std::size_t bodies = rigid ? rigid_count(scene) : particle_count(scene);
  const char* kind = rigid ? " rigid bodies" : " particles";
  for (std::size_t t = 0; t < terms.size(); ++t) {
    if (mixed_bodies(scene)) terms[t].fail("springs join bodies of one kind; the scene has particles and rigid bodies");
    const auto& pairs = scene.springs[t].pairs;
    if (!terms[t].has("pairs")) continue;  // a generator joins its own bodies
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      const std::uint32_t last = std::max(pairs[k].i, pairs[k].j);
      if (last < bodies) continue;
      terms[t].child("pairs").element(k).fail("joins body " + std::to_string(last) + ", but the scene has " +
                                              std::to_string(bodies) + kind);
    }
    check_coincident_ends(scene, rigid, terms[t].child("pairs"), scene.springs[t]);
  }
  check_repeats_across(scene, terms);
  const std::size_t rigids = rigid_count(scene);
  std::size_t k = 0;
  for (const Node& term : body_terms) {
    const Node list = term.child("springs");
    for (std::size_t e = 0; e < list.value.size(); ++e, ++k) {
      const BodySpring& b = scene.body_springs.springs[k];
      const std::uint32_t last = std::max(b.i, b.j);
      if (last >= rigids) {
        list.element(e).fail("joins body " + std::to_string(last) + ", but the scene has " + std::to_string(rigids) +
                             " rigid bodies");
      }
    }
  }
}

}  // namespace kinema
