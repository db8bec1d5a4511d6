// Scene files: the JSON document read into a Scene, every value checked where it stands.
#include "kinema/scene.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <fcntl.h>
#include <initializer_list>
#include <optional>
#include <string>
#include <type_traits>
#include <unistd.h>
#include <variant>
#include <vector>

#include "forces/force_terms.hpp"
#include "scene/scene_checks.hpp"
#include "kinema/error.hpp"
#include "kinema/methods.hpp"
#include "scene/angular_momentum.hpp"
#include "scene/json_document.hpp"
#include "scene/json_node.hpp"
#include "scene/networks.hpp"

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
  n.expect_object({"position", "velocity", "mass", "kinematic", "force", "damping", "gravity_factor"});
  BodySpec b;
  b.position = n.required("position").vec3();
  if (n.has("velocity")) b.velocity = n.child("velocity").vec3();
  if (n.has("kinematic")) b.kinematic = n.child("kinematic").boolean();
  if (n.has("mass")) b.mass = n.child("mass").positive();
  if (n.has("force")) b.force = n.child("force").vec3();
  if (b.kinematic && n.has("force")) n.child("force").fail("a kinematic body ignores forces: give one or the other");
  if (n.has("damping")) b.damping = n.child("damping").non_negative();
  if (n.has("gravity_factor")) b.gravity_factor = n.child("gravity_factor").number();
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

RigidSpec parse_rigid(const Node& n) {
  n.expect_object({"position", "velocity", "orientation", "angular_velocity",
                   "angular_momentum", "mass", "inertia", "force", "torque", "damping", "angular_damping",
                   "gravity_factor", "kinematic"});
  RigidSpec b;
  if (n.has("kinematic")) b.kinematic = n.child("kinematic").boolean();
  for (const char* key : {"force", "torque"}) {
    if (b.kinematic && n.has(key)) n.child(key).fail("a kinematic body ignores forces: give one or the other");
  }
  b.position = n.required("position").vec3();
  if (n.has("velocity")) b.velocity = n.child("velocity").vec3();
  if (n.has("mass")) b.mass = n.child("mass").positive();
  if (n.has("force")) b.force = n.child("force").vec3();
  if (n.has("torque")) b.torque = n.child("torque").vec3();
  if (n.has("damping")) b.damping = n.child("damping").non_negative();
  if (n.has("angular_damping")) b.angular_damping = n.child("angular_damping").non_negative();
  if (n.has("gravity_factor")) b.gravity_factor = n.child("gravity_factor").number();
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

// Everything but the bodies and the forces: name, precision, method, steps, tolerances.
void parse_settings(const Node& root, Scene& s) {
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
}

// A list of bodies under `key`, each read by `parse`.
template <class Spec, class Parse>
void parse_list(const Node& root, const char* key, std::vector<Spec>& out, Parse&& parse) {
  if (!root.has(key)) return;
  const Node list = root.child(key);
  if (!list.value.is_array()) list.fail("expected an array");
  for (std::size_t i = 0; i < list.value.size(); ++i) out.push_back(parse(list.element(i)));
}

void parse_bodies(const Node& root, Scene& s) {
  parse_list(root, "particles", s.particles, parse_body);
  parse_list(root, "rigid_bodies", s.rigid_bodies, parse_rigid);
  if (root.has("generate")) s.generate = parse_generate(root.child("generate"));
}

// Local terms, then the coupled ones (N-body, spring networks), checked together at the end.
void parse_forces(const Node& root, Scene& s) {
  std::vector<Node> spring_terms, body_spring_terms;
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
      if (type == "nbody" && mixed_bodies(s)) {
        term.fail("nbody acts among bodies of one kind; the scene has particles and rigid bodies");
      }
      parse_coupled_force(term, type, s);
      if (type == "springs") spring_terms.push_back(term);
      if (type == "body_springs") body_spring_terms.push_back(term);
    }
  }
  check_coupled(s, spring_terms, body_spring_terms);
}

// One direction word: "either", or the two the kind names its crossings by.
Crossing parse_direction(const Node& n, const char* down, const char* up) {
  const std::string word = n.string();
  if (word == down) return Crossing::down;
  if (word == up) return Crossing::up;
  if (word == "either") return Crossing::either;
  n.fail(std::string("expected \"") + down + "\", \"" + up + "\" or \"either\"");
}

EventSpec parse_event(const Node& n) {
  const std::string type = n.required("type").string();
  EventSpec e;
  const char* down = "down";
  const char* up = "up";
  if (type == "plane") {
    n.expect_object({"type", "normal", "offset", "direction", "action"});
    PlaneEvent plane;
    if (n.has("normal")) plane.normal = n.child("normal").vec3();
    if (plane.normal == Vec3<double>{0, 0, 0}) n.child("normal").fail("expected a normal that is not zero");
    if (n.has("offset")) plane.offset = n.child("offset").number();
    e.kind = plane;
  } else if (type == "distance") {
    n.expect_object({"type", "point", "radius", "direction", "action"});
    DistanceEvent distance;
    if (n.has("point")) distance.point = n.child("point").vec3();
    distance.radius = n.required("radius").positive();
    e.kind = distance;
    down = "inward", up = "outward";
  } else if (type == "speed") {
    n.expect_object({"type", "speed", "direction", "action"});
    e.kind = SpeedEvent{n.required("speed").non_negative()};
  } else {
    n.child("type").fail("expected \"plane\", \"distance\" or \"speed\"");
  }
  if (n.has("direction")) e.direction = parse_direction(n.child("direction"), down, up);
  if (n.has("action")) {
    const Node action = n.child("action");
    const std::string word = action.string();
    if (word != "record" && word != "stop") action.fail("expected \"record\" or \"stop\"");
    e.action = word == "stop" ? EventAction::stop : EventAction::record;
  }
  return e;
}

// Events watch one kind of body, under local terms (a rigid body's centre moving alone).
void check_events(const Node& events, const Scene& s) {
  if (mixed_bodies(s)) events.fail("events watch bodies of one kind; the scene has particles and rigid bodies");
  if (s.nbody || !s.springs.empty()) events.fail("events are watched with local terms only: not with nbody or springs");
  if (rigid_count(s) == 0) return;
  const auto point_spring = [](const LocalTerm& t) { return std::holds_alternative<PointSpring>(t); };
  if (!s.body_springs.springs.empty() || std::any_of(s.forces.begin(), s.forces.end(), point_spring)) {
    events.fail("events on rigid bodies are watched with local terms only: not with body_springs or point_spring");
  }
}

// A dynamic body at an attractor's centre feels an infinite pull from the first step (mu /
// r^2 at r = 0): refused where it is named (a listed body, or the network that made it), not
// reported later as a blow-up.
template <class Spec>
void check_off_centres(const Node& root, const char* key, const std::vector<Spec>& bodies, const Scene& s) {
  for (const LocalTerm& term : s.forces) {
    const auto* central = std::get_if<Central>(&term);
    if (central == nullptr || central->mu == 0) continue;
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      if (bodies[i].kinematic || bodies[i].position != central->center) continue;  // no force moves a kinematic body
      const char* why = "sits at the centre of a central term (mu / r^2 is infinite there)";
      if (const Scene::Generated* g = std::is_same_v<Spec, BodySpec> ? generator_of(s, i) : nullptr) {
        throw Error(printable(std::string(root.origin) + ": " + g->path + ": its body " + std::to_string(i - g->first) +
                              " " + why));
      }
      root.child(key).element(i).fail(why);
    }
  }
}

}  // namespace

Scene parse_scene(std::string_view text, std::string_view origin) {
  const json doc = scene_json::parse_json(text, origin);
  const Node root{doc, "", origin};
  root.expect_object({"name", "precision", "method", "tolerance", "rtol", "atol", "dt", "steps", "particles",
                      "rigid_bodies", "generate", "forces", "events"});
  Scene s;
  parse_settings(root, s);
  parse_bodies(root, s);
  parse_forces(root, s);
  check_off_centres(root, "particles", s.particles, s);
  check_off_centres(root, "rigid_bodies", s.rigid_bodies, s);
  parse_list(root, "events", s.events, parse_event);
  if (!s.events.empty()) check_events(root.child("events"), s);
  if (s.particles.empty() && s.rigid_bodies.empty() && (!s.generate || s.generate->count == 0)) {
    root.fail("the scene has no bodies (give 'particles', 'rigid_bodies' or 'generate')");
  }
  return s;
}

Scene load_scene(const std::filesystem::path& path) {
  const std::string name = printable(path.string());
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) throw Error(name + ": is a directory, not a scene file");
  // O_NONBLOCK for the open alone: a FIFO nobody writes to must not hold it forever (with no
  // writer its read ends at once, empty), and signals must still be answered.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw Error(name + ": cannot open the file (" + std::strerror(errno) + ")");
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  // In chunks, up to one byte past the cap: a device or a pipe may never end.
  std::string text;
  char chunk[1 << 16];
  ssize_t n = 0;
  while (text.size() <= kMaxSceneBytes && ((n = ::read(fd, chunk, sizeof chunk)) > 0 || (n < 0 && errno == EINTR))) {
    if (n > 0) text.append(chunk, std::size_t(n));
  }
  ::close(fd);
  if (n < 0) throw Error(name + ": cannot read the file");
  if (text.size() > kMaxSceneBytes) {
    throw Error(name + ": larger than " + std::to_string(kMaxSceneBytes >> 20) +
                " MiB, the limit for a scene file (use \"generate\" for large scenes)");
  }
  return parse_scene(text, path.string());
}

}  // namespace kinema
