#include "kinema/scene.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <random>
#include <sstream>

#include <nlohmann/json.hpp>

#include "kinema/error.hpp"
#include "kinema/methods.hpp"

namespace kinema {

std::string_view precision_name(Precision p) { return p == Precision::single ? "float" : "double"; }

namespace {

using json = nlohmann::json;

// A JSON value with the path that leads to it, for error messages.
struct Node {
  const json& value;
  std::string path;
  std::string_view origin;

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(std::string(origin) + ": " + (path.empty() ? "(top level)" : path) + ": " + what);
  }
  Node child(const std::string& key) const {
    return {value.at(key), path.empty() ? key : path + "." + key, origin};
  }
  Node element(std::size_t i) const {
    return {value.at(i), path + "[" + std::to_string(i) + "]", origin};
  }
  bool has(const std::string& key) const { return value.contains(key); }

  void expect_object(std::initializer_list<std::string_view> known) const {
    if (!value.is_object()) fail("expected an object");
    for (const auto& [key, _] : value.items()) {
      if (key == "comment" || key == "description") continue;
      if (std::find(known.begin(), known.end(), key) == known.end()) {
        std::string list;
        for (auto k : known) list += (list.empty() ? "" : ", ") + std::string(k);
        child(key).fail("unknown key (known: " + list + ")");
      }
    }
  }
  double number() const {
    if (!value.is_number()) fail("expected a number");
    const double x = value.get<double>();
    if (!std::isfinite(x)) fail("expected a finite number");
    return x;
  }
  double positive() const {
    const double x = number();
    if (!(x > 0)) fail("expected a number > 0");
    return x;
  }
  double non_negative() const {
    const double x = number();
    if (!(x >= 0)) fail("expected a number >= 0");
    return x;
  }
  std::uint64_t count(bool allow_zero) const {
    if (!value.is_number_integer() || value.get<std::int64_t>() < (allow_zero ? 0 : 1)) {
      fail(allow_zero ? "expected an integer >= 0" : "expected an integer >= 1");
    }
    return value.get<std::uint64_t>();
  }
  std::string string() const {
    if (!value.is_string()) fail("expected a string");
    return value.get<std::string>();
  }
  bool boolean() const {
    if (!value.is_boolean()) fail("expected true or false");
    return value.get<bool>();
  }
  Vec3<double> vec3() const {
    if (!value.is_array() || value.size() != 3) fail("expected an array of 3 numbers");
    return {element(0).number(), element(1).number(), element(2).number()};
  }
  Node required(const std::string& key) const {
    if (!has(key)) fail("missing key '" + key + "'");
    return child(key);
  }
};

LocalTerm parse_force(const Node& n) {
  if (!n.value.is_object()) n.fail("expected an object");
  const std::string type = n.required("type").string();
  if (type == "gravity") {
    n.expect_object({"type", "g"});
    return Gravity{n.required("g").vec3()};
  }
  if (type == "linear_drag") {
    n.expect_object({"type", "k"});
    return LinearDrag{n.required("k").non_negative()};
  }
  if (type == "quadratic_drag") {
    n.expect_object({"type", "k"});
    return QuadraticDrag{n.required("k").non_negative()};
  }
  if (type == "spring") {
    n.expect_object({"type", "anchor", "k", "damping"});
    Spring s;
    if (n.has("anchor")) s.anchor = n.child("anchor").vec3();
    s.k = n.required("k").non_negative();
    if (n.has("damping")) s.damping = n.child("damping").non_negative();
    return s;
  }
  if (type == "central") {
    n.expect_object({"type", "center", "mu"});
    Central c;
    if (n.has("center")) c.center = n.child("center").vec3();
    c.mu = n.required("mu").non_negative();
    return c;
  }
  n.child("type").fail("unknown force '" + type +
                       "' (known: gravity, linear_drag, quadratic_drag, spring, central)");
}

BodySpec parse_body(const Node& n) {
  n.expect_object({"position", "velocity", "mass", "kinematic"});
  BodySpec b;
  b.position = n.required("position").vec3();
  if (n.has("velocity")) b.velocity = n.child("velocity").vec3();
  if (n.has("kinematic")) b.kinematic = n.child("kinematic").boolean();
  if (n.has("mass")) b.mass = n.child("mass").positive();
  return b;
}

void check_box(const Node& n, const char* lo_key, const char* hi_key, const Vec3<double>& lo,
               const Vec3<double>& hi) {
  for (int d = 0; d < 3; ++d) {
    if (lo[d] > hi[d]) {
      n.child(hi_key).fail(std::string("must not be below ") + lo_key + " in any component");
    }
  }
}

GenerateSpec parse_generate(const Node& n) {
  n.expect_object({"count", "seed", "position_min", "position_max", "velocity_min",
                   "velocity_max", "mass"});
  GenerateSpec g;
  g.count = n.required("count").count(true);
  if (n.has("seed")) g.seed = n.child("seed").count(true);
  g.position_min = n.required("position_min").vec3();
  g.position_max = n.required("position_max").vec3();
  if (n.has("velocity_min")) g.velocity_min = n.child("velocity_min").vec3();
  if (n.has("velocity_max")) g.velocity_max = n.child("velocity_max").vec3();
  if (n.has("mass")) g.mass = n.child("mass").positive();
  check_box(n, "position_min", "position_max", g.position_min, g.position_max);
  check_box(n, "velocity_min", "velocity_max", g.velocity_min, g.velocity_max);
  return g;
}

// Uniform in [lo, hi] from the top 53 bits of a 64-bit Mersenne Twister: the same numbers
// on every platform (std::uniform_real_distribution is implementation-defined).
double uniform(std::mt19937_64& rng, double lo, double hi) {
  const double u = double(rng() >> 11) * 0x1.0p-53;
  return lo + (hi - lo) * u;
}

}  // namespace

Scene parse_scene(std::string_view text, std::string_view origin) {
  json doc;
  try {
    doc = json::parse(text.begin(), text.end());
  } catch (const json::parse_error& e) {
    throw Error(std::string(origin) + ": invalid JSON: " + e.what());
  }
  const Node root{doc, "", origin};
  root.expect_object({"name", "precision", "method", "dt", "steps", "particles", "generate",
                      "forces"});
  Scene s;
  if (root.has("name")) s.name = root.child("name").string();
  if (root.has("precision")) {
    const Node p = root.child("precision");
    const std::string name = p.string();
    if (name == "float") {
      s.precision = Precision::single;
    } else if (name == "double") {
      s.precision = Precision::dual;
    } else {
      p.fail("expected \"float\" or \"double\"");
    }
  }
  if (root.has("method")) {
    const Node m = root.child("method");
    s.method = m.string();
    try {
      method_by_name(s.method);
    } catch (const Error& e) {
      m.fail(e.what());
    }
  }
  if (root.has("dt")) s.dt = root.child("dt").positive();
  if (root.has("steps")) s.steps = root.child("steps").count(true);
  if (root.has("particles")) {
    const Node list = root.child("particles");
    if (!list.value.is_array()) list.fail("expected an array");
    for (std::size_t i = 0; i < list.value.size(); ++i) {
      s.particles.push_back(parse_body(list.element(i)));
    }
  }
  if (root.has("generate")) s.generate = parse_generate(root.child("generate"));
  if (root.has("forces")) {
    const Node list = root.child("forces");
    if (!list.value.is_array()) list.fail("expected an array");
    for (std::size_t i = 0; i < list.value.size(); ++i) {
      s.forces.push_back(parse_force(list.element(i)));
    }
  }
  if (s.particles.empty() && (!s.generate || s.generate->count == 0)) {
    root.fail("the scene has no bodies (give 'particles' or 'generate')");
  }
  return s;
}

Scene load_scene(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path.string() + ": cannot open the file");
  std::ostringstream text;
  text << in.rdbuf();
  return parse_scene(text.str(), path.string());
}

template <class T>
ParticleSet<T> make_particles(const Scene& scene) {
  auto v3 = [](const Vec3<double>& v) { return Vec3<T>{T(v[0]), T(v[1]), T(v[2])}; };
  ParticleSet<T> set;
  const std::size_t generated = scene.generate ? scene.generate->count : 0;
  set.reserve(scene.particles.size() + generated);
  for (const BodySpec& b : scene.particles) {
    if (b.kinematic) {
      set.add_kinematic(v3(b.position), v3(b.velocity));
    } else {
      set.add(v3(b.position), v3(b.velocity), T(b.mass));
    }
  }
  if (generated > 0) {
    const GenerateSpec& g = *scene.generate;
    std::mt19937_64 rng(g.seed);
    for (std::size_t i = 0; i < g.count; ++i) {
      Vec3<T> p, v;
      for (int d = 0; d < 3; ++d) p[d] = T(uniform(rng, g.position_min[d], g.position_max[d]));
      for (int d = 0; d < 3; ++d) v[d] = T(uniform(rng, g.velocity_min[d], g.velocity_max[d]));
      set.add(p, v, T(g.mass));
    }
  }
  return set;
}

template <class T>
ForceModel<T> make_forces(const Scene& scene) {
  ForceModel<T> model;
  for (std::size_t i = 0; i < scene.forces.size(); ++i) {
    try {
      model.add(scene.forces[i]);
    } catch (const Error& e) {
      throw Error("forces[" + std::to_string(i) + "]: " + e.what());
    }
  }
  return model;
}

template ParticleSet<float> make_particles<float>(const Scene&);
template ParticleSet<double> make_particles<double>(const Scene&);
template ForceModel<float> make_forces<float>(const Scene&);
template ForceModel<double> make_forces<double>(const Scene&);

}  // namespace kinema
