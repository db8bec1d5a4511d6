#include "kinema/scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <initializer_list>
#include <numbers>
#include <random>
#include <set>

#include <sys/resource.h>
#include <unistd.h>

#include "core/text.hpp"
#include "forces/force_terms.hpp"
#include "scene/json_node.hpp"
#include "scene/networks.hpp"
#include "kinema/error.hpp"
#include "kinema/job_system.hpp"
#include "kinema/methods.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

std::string_view precision_name(Precision p) { return p == Precision::single ? "float" : "double"; }

namespace {

using scene_json::json;
using scene_json::Node;

// A term from its home's fields: the keys it knows, vectors and numbers >= 0.
template <class Term, class Info>
Term parse_term(const Node& n, Info info) {
  std::vector<std::string_view> keys{"type"};
  for_each_field(info, [&](const auto& field) { keys.push_back(field.key); });
  n.expect_object(keys);
  Term term;
  for_each_field(info, [&](const auto& field) {
    if (!field.required && !n.has(field.key)) return;
    const Node value = n.child(field.key);
    if constexpr (std::decay_t<decltype(field)>::is_vector) {
      term.*field.member = value.vec3();
    } else {
      term.*field.member = value.non_negative();
    }
  });
  return term;
}

LocalTerm parse_force(const Node& n) {
  if (!n.value.is_object()) n.fail("expected an object");
  const std::string type = n.required("type").string();
  std::optional<LocalTerm> term;
  std::string known;
  for_each_term([&]<class Term>() {
    constexpr TermInfo<Term> info;
    known += (known.empty() ? "" : ", ") + std::string(info.name);
    if (type == info.name) term = parse_term<Term>(n, info);
  });
  if (!term) n.child("type").fail("unknown force '" + type + "' (known: " + known + ")");
  return *term;
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

// Either bound may be left out (it is then 0): the error names one the scene gave.
void check_box(const Node& n, const char* lo_key, const char* hi_key, const Vec3<double>& lo,
               const Vec3<double>& hi) {
  for (int d = 0; d < 3; ++d) {
    if (lo[d] <= hi[d]) continue;
    if (n.has(hi_key)) n.child(hi_key).fail(std::string("must not be below ") + lo_key + " in any component");
    n.child(lo_key).fail(std::string("must not be above ") + hi_key + " (0 when left out) in any component");
  }
}

// Principal moments, from [Ixx, Iyy, Izz] or a symmetric 3x3 matrix; the rotation from the
// principal frame to the given body frame comes back through out_turn.
Vec3<double> parse_inertia(const Node& n, Quat<double>& out_turn) {
  out_turn = {1, 0, 0, 0};
  if (n.value.is_array() && n.value.size() == 3 && n.value[0].is_array()) {
    std::array<std::array<double, 3>, 3> tensor;
    for (std::size_t i = 0; i < 3; ++i) {
      const Node row = n.element(i);
      tensor[i] = row.vec3();
    }
    try {
      const PrincipalFrame frame = principal_frame(tensor);
      out_turn = frame.rotation;
      return frame.moments;
    } catch (const Error& e) {
      n.fail(std::string(e.what()).substr(9));  // drop the "inertia: " prefix
    }
  }
  if (!n.value.is_array() || n.value.size() != 3) {
    n.fail("expected [Ixx, Iyy, Izz] or a 3x3 matrix");
  }
  const Vec3<double> moments = n.vec3();
  for (std::size_t i = 0; i < 3; ++i) {
    if (!(moments[i] > 0)) n.element(i).fail("expected a number > 0");
  }
  return moments;
}

Quat<double> parse_orientation(const Node& n) {
  if (!n.value.is_array() || n.value.size() != 4) n.fail("expected [w, x, y, z]");
  Quat<double> q;
  double largest = 0;
  for (std::size_t k = 0; k < 4; ++k) q[k] = n.element(k).number(), largest = std::max(largest, std::abs(q[k]));
  if (!(largest > 0)) n.fail("the quaternion is zero");
  // Scaled by the largest component first, so neither tiny nor huge ones under- or overflow.
  double norm = 0;
  for (double& c : q) c /= largest, norm += c * c;
  for (double& c : q) c /= std::sqrt(norm);
  return q;
}

// L = R diag(I) R^T omega, all in double.
Vec3<double> momentum_from_velocity(const Quat<double>& q, const Vec3<double>& inertia,
                                    const Vec3<double>& omega) {
  Vec3<double> body = rotate({q[0], -q[1], -q[2], -q[3]}, omega);
  for (int d = 0; d < 3; ++d) body[d] *= inertia[d];
  return rotate(q, body);
}

RigidSpec parse_rigid(const Node& n) {
  n.expect_object({"position", "velocity", "orientation", "angular_velocity",
                   "angular_momentum", "mass", "inertia"});
  RigidSpec b;
  b.position = n.required("position").vec3();
  if (n.has("velocity")) b.velocity = n.child("velocity").vec3();
  if (n.has("mass")) b.mass = n.child("mass").positive();
  Quat<double> given{1, 0, 0, 0}, turn{1, 0, 0, 0};
  if (n.has("orientation")) given = parse_orientation(n.child("orientation"));
  if (n.has("inertia")) b.inertia = parse_inertia(n.child("inertia"), turn);
  b.orientation = multiply(given, turn);
  if (n.has("angular_velocity") && n.has("angular_momentum")) {
    n.child("angular_momentum").fail("give angular_velocity or angular_momentum, not both");
  }
  if (n.has("angular_momentum")) b.angular_momentum = n.child("angular_momentum").vec3();
  if (n.has("angular_velocity")) {
    b.angular_momentum =
        momentum_from_velocity(b.orientation, b.inertia, n.child("angular_velocity").vec3());
  }
  return b;
}

// The keys of the Plummer form: no boxes, no rigid bodies.
void parse_plummer(const Node& n, GenerateSpec& g) {
  const Node d = n.child("distribution");
  if (d.string() != "plummer") d.fail("expected \"box\" or \"plummer\"");
  if (g.rigid) d.fail("a Plummer sphere is made of particles");
  for (const char* key : {"position_min", "position_max", "velocity_min", "velocity_max", "inertia",
                          "angular_velocity_min", "angular_velocity_max"}) {
    if (n.has(key)) n.child(key).fail("only for \"distribution\": \"box\"");
  }
  g.plummer_radius = n.required("radius").positive();
}

GenerateSpec parse_generate(const Node& n) {
  n.expect_object({"count", "seed", "position_min", "position_max", "velocity_min",
                   "velocity_max", "mass", "kind", "inertia", "angular_velocity_min",
                   "angular_velocity_max", "distribution", "radius"});
  GenerateSpec g;
  g.count = n.required("count").count(true);
  // 2^32 bodies of 7 double arrays is 240 GB: far past any machine this runs on.
  if (g.count > (std::uint64_t(1) << 32)) n.child("count").fail("expected at most 2^32 bodies");
  if (n.has("seed")) g.seed = n.child("seed").count(true);
  if (n.has("mass")) g.mass = n.child("mass").positive();
  if (n.has("kind")) {
    const Node kind = n.child("kind");
    const std::string name = kind.string();
    if (name != "particle" && name != "rigid") kind.fail("expected \"particle\" or \"rigid\"");
    g.rigid = name == "rigid";
  }
  const bool plummer = n.has("distribution") && n.child("distribution").string() != "box";
  if (plummer) {
    parse_plummer(n, g);
    return g;
  }
  if (n.has("radius")) n.child("radius").fail("only for \"distribution\": \"plummer\"");
  g.position_min = n.required("position_min").vec3();
  g.position_max = n.required("position_max").vec3();
  if (n.has("velocity_min")) g.velocity_min = n.child("velocity_min").vec3();
  if (n.has("velocity_max")) g.velocity_max = n.child("velocity_max").vec3();
  for (const char* key : {"inertia", "angular_velocity_min", "angular_velocity_max"}) {
    if (n.has(key) && !g.rigid) n.child(key).fail("only for \"kind\": \"rigid\"");
  }
  if (n.has("inertia")) {
    Quat<double> turn;
    const Node inertia = n.child("inertia");
    g.inertia = parse_inertia(inertia, turn);
    if (turn != Quat<double>{1, 0, 0, 0}) inertia.fail("expected principal moments [Ixx, Iyy, Izz]");
  }
  if (n.has("angular_velocity_min")) g.angular_velocity_min = n.child("angular_velocity_min").vec3();
  if (n.has("angular_velocity_max")) g.angular_velocity_max = n.child("angular_velocity_max").vec3();
  check_box(n, "position_min", "position_max", g.position_min, g.position_max);
  check_box(n, "velocity_min", "velocity_max", g.velocity_min, g.velocity_max);
  check_box(n, "angular_velocity_min", "angular_velocity_max", g.angular_velocity_min,
            g.angular_velocity_max);
  return g;
}

// Uniform in [lo, hi] from the top 53 bits of a 64-bit Mersenne Twister: the same numbers
// on every platform (std::uniform_real_distribution is implementation-defined).
double uniform(std::mt19937_64& rng, double lo, double hi) {
  const double u = double(rng() >> 11) * 0x1.0p-53;
  return lo + (hi - lo) * u;
}

// Builds the document from the parser's events (SAX), keeping the path it is at: an error
// the JSON library finds (a number out of range, a syntax error) names its path, a repeated
// key is refused (the library would keep the last one silently), and so is nesting past
// kMaxDepth. Linear in the text: the library's own callback mode rescans each parent array
// whenever an element ends.
class DocumentBuilder : public nlohmann::json_sax<json> {
 public:
  static constexpr std::size_t kMaxDepth = 64;

  struct Stop {  // thrown to stop the parse; path() says where
    std::string what;
  };

  json document;

  bool null() override { return value(nullptr); }
  bool boolean(bool v) override { return value(v); }
  bool number_integer(number_integer_t v) override { return value(v); }
  bool number_unsigned(number_unsigned_t v) override { return value(v); }
  bool number_float(number_float_t v, const string_t&) override { return value(v); }
  bool string(string_t& v) override { return value(std::move(v)); }
  bool binary(binary_t& v) override { return value(json::binary(std::move(v))); }
  bool start_object(std::size_t) override { return open(json::object()); }
  bool start_array(std::size_t) override { return open(json::array()); }
  bool end_object() override { return close(); }
  bool end_array() override { return close(); }

  bool key(string_t& k) override {
    Frame& f = frames_.back();
    f.key = k;
    f.in_key = true;
    if (!f.keys.insert(k).second) throw Stop{"duplicate key (each key may appear once)"};
    f.slot = &(*f.node)[k];
    return true;
  }

  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception& e) override {
    throw Stop{std::string("invalid JSON: ") + e.what()};
  }

  // Where the parser is: "forces[2].k", or "" at the top level.
  std::string path() const {
    std::string out;
    for (std::size_t i = 0; i < frames_.size(); ++i) {
      const Frame& f = frames_[i];
      if (f.node->is_object() && f.in_key) out += (out.empty() ? "" : ".") + f.key;
      if (!f.node->is_array()) continue;
      // The innermost array is reading its next element; an outer one, its last.
      const std::size_t index = f.node->size() - (i + 1 < frames_.size() ? 1 : 0);
      out += "[" + std::to_string(index) + "]";
    }
    return out;
  }

 private:
  struct Frame {
    json* node;
    json* slot = nullptr;  // objects: the value of the key being read
    std::string key;
    bool in_key = false;   // objects: reading the value of `key`
    std::set<std::string> keys;
  };

  // Where the next value goes: the document, the next array element, or the key's slot.
  json* place(json&& v) {
    if (frames_.empty()) return &(document = std::move(v));
    Frame& f = frames_.back();
    if (f.node->is_array()) {
      f.node->push_back(std::move(v));
      return &f.node->back();
    }
    *f.slot = std::move(v);
    return f.slot;
  }
  bool value(json&& v) {
    place(std::move(v));
    end_value();
    return true;
  }
  // A key names the path only until its value is complete.
  void end_value() {
    if (!frames_.empty() && frames_.back().node->is_object()) frames_.back().in_key = false;
  }
  bool open(json&& container) {
    if (frames_.size() == kMaxDepth) {
      throw Stop{"nested deeper than " + std::to_string(kMaxDepth) + " levels"};
    }
    json* node = place(std::move(container));
    frames_.push_back(Frame{node, nullptr, {}, false, {}});
    return true;
  }
  bool close() {
    frames_.pop_back();
    end_value();
    return true;
  }

  std::vector<Frame> frames_;
};

[[noreturn]] void invalid_json(std::string_view origin, const std::string& path,
                               const std::string& what) {
  throw Error(printable(std::string(origin) + ": " + (path.empty() ? "" : path + ": ") + what));
}

json parse_json(std::string_view text, std::string_view origin) {
  if (const std::size_t nul = text.find('\0'); nul != std::string_view::npos) {
    invalid_json(origin, "", "invalid JSON: a NUL byte at offset " + std::to_string(nul));
  }
  DocumentBuilder builder;
  try {
    json::sax_parse(text.begin(), text.end(), &builder);
  } catch (const DocumentBuilder::Stop& stop) {
    invalid_json(origin, builder.path(), stop.what);
  }
  return std::move(builder.document);
}

}  // namespace

Scene parse_scene(std::string_view text, std::string_view origin) {
  const json doc = parse_json(text, origin);
  const Node root{doc, "", origin};
  root.expect_object({"name", "precision", "method", "tolerance", "rtol", "atol", "dt", "steps", "particles",
                      "rigid_bodies", "generate", "forces"});
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
      if (s.method != "auto") method_by_name(s.method);
    } catch (const Error& e) {
      m.fail(std::string(e.what()) + " or auto");
    }
  }
  if (root.has("dt")) s.dt = root.child("dt").positive();
  if (root.has("steps")) s.steps = root.child("steps").count(true);
  if (root.has("tolerance")) s.tolerance = root.child("tolerance").positive();
  if (root.has("rtol")) s.rtol = root.child("rtol").positive();
  if (root.has("atol")) s.atol = root.child("atol").positive();
  if (root.has("particles")) {
    const Node list = root.child("particles");
    if (!list.value.is_array()) list.fail("expected an array");
    for (std::size_t i = 0; i < list.value.size(); ++i) {
      s.particles.push_back(parse_body(list.element(i)));
    }
  }
  if (root.has("rigid_bodies")) {
    const Node list = root.child("rigid_bodies");
    if (!list.value.is_array()) list.fail("expected an array");
    for (std::size_t i = 0; i < list.value.size(); ++i) {
      s.rigid_bodies.push_back(parse_rigid(list.element(i)));
    }
  }
  if (root.has("generate")) s.generate = parse_generate(root.child("generate"));
  std::vector<Node> spring_terms;
  if (root.has("forces")) {
    const Node list = root.child("forces");
    if (!list.value.is_array()) list.fail("expected an array");
    for (std::size_t i = 0; i < list.value.size(); ++i) {
      const Node term = list.element(i);
      const std::string type = term.value.is_object() && term.has("type") ? term.child("type").string() : "";
      if (!is_coupled_force(type)) {
        s.forces.push_back(parse_force(term));
        continue;
      }
      if (type == "nbody" && (!s.rigid_bodies.empty() || (s.generate && s.generate->rigid))) {
        term.fail("nbody acts on particles only; the scene has rigid bodies");
      }
      parse_coupled_force(term, type, s);
      if (type == "springs") spring_terms.push_back(term);
    }
  }
  check_coupled(s, spring_terms);
  if (s.particles.empty() && s.rigid_bodies.empty() && (!s.generate || s.generate->count == 0)) {
    root.fail("the scene has no bodies (give 'particles', 'rigid_bodies' or 'generate')");
  }
  return s;
}

Scene load_scene(const std::filesystem::path& path) {
  const std::string name = printable(path.string());
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) throw Error(name + ": is a directory, not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(name + ": cannot open the file");
  // In chunks, up to one byte past the cap: a device or a pipe may never end.
  std::string text;
  char chunk[1 << 16];
  while (text.size() <= kMaxSceneBytes && in.read(chunk, sizeof chunk).gcount() > 0) {
    text.append(chunk, std::size_t(in.gcount()));
  }
  if (in.bad()) throw Error(name + ": cannot read the file");
  if (text.size() > kMaxSceneBytes) {
    throw Error(name + ": larger than " + std::to_string(kMaxSceneBytes >> 20) +
                " MiB, the limit for a scene file (use \"generate\" for large scenes)");
  }
  return parse_scene(text, path.string());
}

namespace {

template <class T>
Vec3<T> converted(const Vec3<double>& v) {
  return {T(v[0]), T(v[1]), T(v[2])};
}

// A uniformly random rotation (Shoemake, "Uniform random rotations", Graphics Gems III).
Quat<double> random_orientation(std::mt19937_64& rng) {
  const double u1 = uniform(rng, 0, 1), u2 = uniform(rng, 0, 2 * std::numbers::pi),
               u3 = uniform(rng, 0, 2 * std::numbers::pi);
  const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
  return {b * std::cos(u3), a * std::sin(u2), a * std::cos(u2), b * std::sin(u3)};
}

}  // namespace

namespace {

// Arrays per body: px py pz vx vy vz inv_mass; rigid bodies add q (4), L (3) and the
// inverse principal moments (3).
constexpr double kParticleArrays = 7, kRigidArrays = 17;

std::string gib(double bytes) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f GiB", bytes / double(1 << 30));
  return text;
}

template <class T>
bool holds(double x) {
  return std::isfinite(T(x));
}

template <class T>
bool holds(const Vec3<double>& v) {
  return holds<T>(v[0]) && holds<T>(v[1]) && holds<T>(v[2]);
}

double largest(const Vec3<double>& v) {
  return std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])});
}

template <class T>
void check_generated(const Scene& scene) {
  if (!scene.generate) return;
  const GenerateSpec& g = *scene.generate;
  const std::string type = type_name<T>();
  auto fail = [&](const std::string& key, const std::string& what) {
    throw Error(printable("generate." + key + ": " + what));
  };
  const double need = state_bytes<T>(scene), have = usable_memory_bytes();
  if (need > have) {
    fail("count", std::to_string(g.count) + (g.rigid ? " rigid bodies" : " particles") + " in " +
                      type + " need " + gib(need) + " of state, more than the " + gib(have) +
                      " this process may use");
  }
  const T inv_mass = T(1) / T(g.mass);
  if (!(std::isfinite(inv_mass) && inv_mass > 0)) {
    fail("mass", "has no finite nonzero inverse in " + type);
  }
  const std::pair<const char*, const Vec3<double>*> boxes[] = {
      {"position_min", &g.position_min}, {"position_max", &g.position_max},
      {"velocity_min", &g.velocity_min}, {"velocity_max", &g.velocity_max},
      {"angular_velocity_min", &g.angular_velocity_min},
      {"angular_velocity_max", &g.angular_velocity_max}};
  for (const auto& [key, box] : boxes) {
    if (!holds<T>(*box)) fail(key, "overflows " + type);
  }
  if (g.plummer_radius > 0) {
    if (!holds<T>(40 * g.plummer_radius)) fail("radius", "overflows " + type);
    const double GM = (scene.nbody ? scene.nbody->G : 1) * g.mass * double(g.count);
    if (!holds<T>(std::sqrt(2 * GM / g.plummer_radius))) {
      fail("mass", "the cluster's escape speed overflows " + type);
    }
  }
  if (!g.rigid) return;
  for (int d = 0; d < 3; ++d) {
    const T inverse = T(1) / T(g.inertia[d]);
    if (!(std::isfinite(inverse) && inverse > 0)) fail("inertia", "a moment has no finite inverse in " + type);
  }
  // |L| <= max moment x |omega| <= max moment x sqrt(3) x largest component.
  const double omega = std::max(largest(g.angular_velocity_min), largest(g.angular_velocity_max));
  if (!holds<T>(largest(g.inertia) * std::sqrt(3.0) * omega)) {
    fail("angular_velocity_max", "the angular momentum it gives overflows " + type);
  }
}

// Listed masses that T cannot invert (1e-50 is 0 in float), named by their JSON path.
template <class T>
void check_listed_masses(const Scene& scene) {
  auto check = [](const char* list, std::size_t i, double mass) {
    const T inverse = T(1) / T(mass);
    if (!(std::isfinite(inverse) && inverse > 0)) {
      char text[160];
      std::snprintf(text, sizeof text, "%s[%zu].mass: %g has no finite nonzero inverse in %s", list,
                    i, mass, type_name<T>().c_str());
      throw Error(text);
    }
  };
  for (std::size_t i = 0; i < scene.particles.size(); ++i) {
    if (!scene.particles[i].kinematic) check("particles", i, scene.particles[i].mass);
  }
  for (std::size_t i = 0; i < scene.rigid_bodies.size(); ++i) check("rigid_bodies", i, scene.rigid_bodies[i].mass);
}

}  // namespace

double usable_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  double bytes = pages > 0 && page > 0 ? double(pages) * double(page) : HUGE_VAL;
  rlimit limit{};
  if (::getrlimit(RLIMIT_AS, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY) {
    bytes = std::min(bytes, double(limit.rlim_cur));
  }
  // cgroup v2 ("max" when unlimited, then the read fails and nothing changes).
  std::ifstream cgroup("/sys/fs/cgroup/memory.max");
  double cgroup_bytes = 0;
  if (cgroup >> cgroup_bytes && cgroup_bytes > 0) bytes = std::min(bytes, cgroup_bytes);
  return bytes;
}

template <class T>
double state_bytes(const Scene& scene) {
  const bool rigid = scene.generate && scene.generate->rigid;
  const double generated = scene.generate ? double(scene.generate->count) : 0;
  const double particles = double(scene.particles.size()) + (rigid ? 0 : generated);
  const double rigid_bodies = double(scene.rigid_bodies.size()) + (rigid ? generated : 0);
  return (particles * kParticleArrays + rigid_bodies * kRigidArrays) * double(sizeof(T));
}

template <class T>
void check_scene(const Scene& scene) {
  check_listed_masses<T>(scene);
  check_generated<T>(scene);
  const ForceModel<T> forces = make_forces<T>(scene);
  // Lowering the forces to T checks their sums; auto picks its own dt later.
  const Method& method = scene.method == "auto" ? rk4 : method_by_name(scene.method);
  std::optional<Stepper<T>> stepper;
  try {
    stepper.emplace(forces, method, on_calling_thread());
  } catch (const Error& e) {
    throw Error(std::string("forces: ") + e.what());
  }
  if (scene.method == "auto") return;
  try {
    stepper->check_step_size(T(scene.dt));
  } catch (const Error& e) {
    throw Error(std::string("dt: ") + e.what());
  }
}

template <class T>
RigidBodySet<T> make_rigid_bodies(const Scene& scene) {
  check_generated<T>(scene);
  RigidBodySet<T> set;
  const bool generated = scene.generate && scene.generate->rigid;
  set.reserve(scene.rigid_bodies.size() + (generated ? scene.generate->count : 0));
  auto add = [&](const RigidSpec& b) {
    set.add({converted<T>(b.position), converted<T>(b.velocity),
             {T(b.orientation[0]), T(b.orientation[1]), T(b.orientation[2]), T(b.orientation[3])},
             converted<T>(b.angular_momentum), T(b.mass), converted<T>(b.inertia)});
  };
  for (const RigidSpec& b : scene.rigid_bodies) add(b);
  if (generated) {
    const GenerateSpec& g = *scene.generate;
    std::mt19937_64 rng(g.seed);
    for (std::size_t i = 0; i < g.count; ++i) {
      RigidSpec b;
      for (int d = 0; d < 3; ++d) b.position[d] = uniform(rng, g.position_min[d], g.position_max[d]);
      for (int d = 0; d < 3; ++d) b.velocity[d] = uniform(rng, g.velocity_min[d], g.velocity_max[d]);
      Vec3<double> omega;
      for (int d = 0; d < 3; ++d) {
        omega[d] = uniform(rng, g.angular_velocity_min[d], g.angular_velocity_max[d]);
      }
      b.orientation = random_orientation(rng);
      b.mass = g.mass;
      b.inertia = g.inertia;
      b.angular_momentum = momentum_from_velocity(b.orientation, b.inertia, omega);
      add(b);
    }
  }
  return set;
}

namespace {

// A uniformly random direction (Marsaglia's method), and the Plummer sampling below, use
// only exactly rounded operations (+ - * / sqrt): the same bodies on every platform.
Vec3<double> random_direction(std::mt19937_64& rng) {
  double u = 0, v = 0, s = 2;
  while (s >= 1 || s == 0) u = uniform(rng, -1, 1), v = uniform(rng, -1, 1), s = u * u + v * v;
  const double scale = 2 * std::sqrt(1 - s);
  return {u * scale, v * scale, 1 - 2 * s};
}

// One body of a Plummer sphere (scale a, total mass M), positions cut at 20 a. The mass
// inside r is M X^(3/2) with X = r^2 / (r^2 + a^2); X, whose density is proportional to
// sqrt(X), comes by rejection, then r = a sqrt(X / (1 - X)). The speed is q times the escape
// speed sqrt(2 G M) (r^2 + a^2)^(-1/4), q by rejection from g(q) = q^2 (1 - q^2)^(7/2)
// (Aarseth, Henon and Wielen, 1974; g < 0.1).
void plummer_body(std::mt19937_64& rng, double a, double GM, Vec3<double>& x, Vec3<double>& v) {
  double r = INFINITY;
  while (!(r <= 20 * a)) {
    double X = 0, w = 1;
    while (w * w > X) X = uniform(rng, 0, 1), w = uniform(rng, 0, 1);
    r = a * std::sqrt(X / (1 - X));
  }
  double q = 0, g = 1;
  for (double s = 0; g > q * q * s * s * s * std::sqrt(s);) {
    q = uniform(rng, 0, 1), g = uniform(rng, 0, 0.1), s = 1 - q * q;
  }
  const double speed = q * std::sqrt(2 * GM) / std::sqrt(std::sqrt(r * r + a * a));
  const Vec3<double> along = random_direction(rng), heading = random_direction(rng);
  for (int d = 0; d < 3; ++d) x[d] = r * along[d], v[d] = speed * heading[d];
}

// The generated bodies of a Plummer scene, moved so their centre of mass is at rest at the
// origin: a first pass finds the means, a second one, from the same seed, adds the bodies.
template <class T>
void add_plummer(const Scene& scene, ParticleSet<T>& set) {
  const GenerateSpec& g = *scene.generate;
  const double GM = (scene.nbody ? scene.nbody->G : 1) * g.mass * double(g.count);
  Vec3<double> x, v, mean_x{}, mean_v{};
  std::mt19937_64 rng(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    plummer_body(rng, g.plummer_radius, GM, x, v);
    for (int d = 0; d < 3; ++d) mean_x[d] += x[d] / double(g.count), mean_v[d] += v[d] / double(g.count);
  }
  rng.seed(g.seed);
  for (std::size_t i = 0; i < g.count; ++i) {
    plummer_body(rng, g.plummer_radius, GM, x, v);
    Vec3<T> p, u;
    for (int d = 0; d < 3; ++d) p[d] = T(x[d] - mean_x[d]), u[d] = T(v[d] - mean_v[d]);
    set.add(p, u, T(g.mass));
  }
}

}  // namespace

template <class T>
ParticleSet<T> make_particles(const Scene& scene) {
  check_generated<T>(scene);
  auto v3 = [](const Vec3<double>& v) { return converted<T>(v); };
  ParticleSet<T> set;
  const std::size_t generated = scene.generate && !scene.generate->rigid ? scene.generate->count : 0;
  set.reserve(scene.particles.size() + generated);
  for (const BodySpec& b : scene.particles) {
    if (b.kinematic) {
      set.add_kinematic(v3(b.position), v3(b.velocity));
    } else {
      set.add(v3(b.position), v3(b.velocity), T(b.mass));
    }
  }
  if (generated > 0 && scene.generate->plummer_radius > 0) {
    add_plummer(scene, set);
  } else if (generated > 0) {
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
  try {
    if (scene.nbody) model.add(*scene.nbody);
    for (const Springs& network : scene.springs) model.add(network);
  } catch (const Error& e) {
    throw Error(std::string("forces: ") + e.what());
  }
  return model;
}

template RigidBodySet<float> make_rigid_bodies<float>(const Scene&);
template RigidBodySet<double> make_rigid_bodies<double>(const Scene&);
template ParticleSet<float> make_particles<float>(const Scene&);
template ParticleSet<double> make_particles<double>(const Scene&);
template void check_scene<float>(const Scene&);
template void check_scene<double>(const Scene&);
template double state_bytes<float>(const Scene&);
template double state_bytes<double>(const Scene&);
template ForceModel<float> make_forces<float>(const Scene&);
template ForceModel<double> make_forces<double>(const Scene&);

}  // namespace kinema
