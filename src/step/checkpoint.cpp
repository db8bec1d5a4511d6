#include "kinema/checkpoint.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>

#include "kinema/diagnostics.hpp"
#include "core/fnv.hpp"
#include "kinema/error.hpp"
#include "kinema/files.hpp"
#include "step/stepper_access.hpp"

namespace kinema {
namespace {

constexpr char kMagic[8] = {'k', 'i', 'n', 'e', 'm', 'a', 'C', 'K'};
constexpr std::size_t kTrailerBytes = 4;
constexpr std::size_t kMethodNameBytes = 32;

enum class SetKind : std::uint8_t { particles = 1, rigid = 2 };
enum Flags : std::uint8_t {
  kForces = 1,
  kTorques = 2,
  kKeepForces = 4,
  kKeptStage = 8,
  // One array each, after the torques: the per-body parameters a set has set.
  kGravityFactor = 16,
  kLinearDamping = 32,
  kAngularDamping = 64,
};
constexpr std::array<std::pair<Flags, BodyParameter>, 3> kParameterFlags{
    {{kGravityFactor, BodyParameter::gravity_factor},
     {kLinearDamping, BodyParameter::linear_damping},
     {kAngularDamping, BodyParameter::angular_damping}}};
// + 3 for forces, + 3 for torques, + 3 for a kept first stage
constexpr std::size_t kParticleArrays = 7, kRigidArrays = 17;

// Field offsets in the 48-byte header and the 192-byte record header.
namespace head {
constexpr std::size_t version = 8, records = 12, total = 16, user = 24, crc = 44;
}
namespace rec {
constexpr std::size_t kind = 0, scalar = 1, flags = 2, guard = 3, bodies = 8, model = 16, method = 24, origin = 32,
                      steps = 40, h = 48, proposed = 56, max_speed = 64, max_angular = 72, name = 80,
                      // the continuation of an error-controlled call stopped early
                      continues = 112, rejected = 113, relaxed = 114, preconditioner = 115,
                      // rigid steps' renormalize_quaternions: 1 true, 2 false, 0 either (older records)
                      quaternions = 116, t_end = 120, rtol = 128, atol = 136, max_step = 144,
                      next_h = 152, err_prev = 160, kept_scale = 168,
                      // an implicit method's solves (0 for the others)
                      implicit_tolerance = 176, implicit_iterations = 184, crc = 188;
}

template <class V>
void put(std::byte* at, V value) {
  std::memcpy(at, &value, sizeof(V));
}
template <class V>
V get(const std::byte* at) {
  V value;
  std::memcpy(&value, at, sizeof(V));
  return value;
}

std::uint32_t crc_of(const std::byte* data, std::size_t bytes) { return crc32c({data, bytes}); }

// The method as data (tableau or kick-drift scheme), field by field: equal methods, equal hashes.
std::uint64_t method_fingerprint(const Method& m) {
  Fnv fnv;
  fnv.add(int(m.kind)), fnv.add(m.order), fnv.add(m.embedded_order), fnv.add(m.tableau.stages);
  for (const auto& row : m.tableau.a) for (double a : row) fnv.add(a);
  for (const auto* weights : {&m.tableau.b, &m.tableau.c, &m.tableau.b_hat}) for (double w : *weights) fnv.add(w);
  fnv.add(m.scheme.count);
  for (const KickDriftOp& op : m.scheme.ops) fnv.add(int(op.kind)), fnv.add(op.weight), fnv.add(op.time);
  if (m.kind == MethodKind::linearly_implicit) {  // the others' fingerprints stay as they were
    const RosenbrockScheme& r = m.rosenbrock;
    fnv.add(r.stages), fnv.add(r.gamma);
    for (const auto* rows : {&r.a, &r.c}) for (const auto& row : *rows) for (double v : row) fnv.add(v);
    for (const auto* weights : {&r.m, &r.time}) for (double w : *weights) fnv.add(w);
  }
  return fnv.value();
}

// The solves an implicit method's steps make, as the stepper runs them (its options' 0 is
// the precision's default); nothing for the other methods.
struct ImplicitSolves {
  double tolerance = 0;
  std::int32_t iterations = 0;
  std::uint8_t multigrid = 0;  // 2: multigrid, 1: Jacobi; 0 (checkpoints that predate it): Jacobi
};
template <class T>
ImplicitSolves implicit_solves(const Stepper<T>& stepper) {
  if (stepper.method().kind != MethodKind::linearly_implicit) return {};
  const StepperOptions& o = stepper.options();
  const std::size_t network = network_reach(stepper.forces().springs());
  return {o.implicit_tolerance > 0 ? o.implicit_tolerance : kDefaultImplicitTolerance<T>, o.implicit_max_iterations,
          std::uint8_t(takes_multigrid(o.implicit_preconditioner, network) ? 2 : 1)};
}

std::string_view guard_name(std::uint8_t g) { return g == 0 ? "off" : g == 1 ? "check" : "clamp"; }

std::string precision_of(std::size_t scalar) { return scalar == 4 ? "float" : "double"; }

}  // namespace

// The sets' arrays as they are stored: n values each, in a fixed order.
struct detail::CheckpointCodec {
  template <class T>
  static void arrays(const ParticleSet<T>& b, std::vector<const T*>& out) {
    for (const AlignedArray<T>* a : {&b.px_, &b.py_, &b.pz_, &b.vx_, &b.vy_, &b.vz_, &b.inv_mass_}) out.push_back(a->data());
  }
  template <class T>
  static void arrays(const RigidBodySet<T>& b, std::vector<const T*>& out) {
    arrays(b.centers_, out);
    for (const auto& a : b.q_) out.push_back(a.data());
    for (const auto& a : b.l_) out.push_back(a.data());
    for (const auto& a : b.inv_inertia_) out.push_back(a.data());
  }
  template <class T>
  static void applied(const AppliedVectors<T>& v, std::vector<const T*>& out) {
    for (int d = 0; d < 3; ++d) out.push_back(v.data(d));
  }
  // A particle record leaves out angular damping (a set copied from rigid bodies' centres
  // may carry it; particles never read it).
  template <class T>
  static void parameters(const BodyParameters<T>& p, SetKind kind, std::uint8_t& flags, std::vector<const T*>& out) {
    for (const auto& [flag, parameter] : kParameterFlags) {
      if (kind == SetKind::particles && parameter == BodyParameter::angular_damping) continue;
      if (p.used(parameter)) flags |= flag, out.push_back(p.data(parameter));
    }
  }
  template <class T>
  static const BodyParameters<T>& parameters(const ParticleSet<T>& b) { return b.params_; }
  template <class T>
  static const BodyParameters<T>& parameters(const RigidBodySet<T>& b) { return b.centers_.params_; }
  template <class T>
  static const AppliedVectors<T>& forces(const ParticleSet<T>& b) { return b.applied_; }
  template <class T>
  static const AppliedVectors<T>& forces(const RigidBodySet<T>& b) { return b.centers_.applied_; }
  template <class T>
  static const AppliedVectors<T>* torques(const ParticleSet<T>&) { return nullptr; }
  template <class T>
  static const AppliedVectors<T>* torques(const RigidBodySet<T>& b) { return &b.torques_; }

  // Copies `n` values into each array from `at` on, advancing it.
  template <class T>
  static void fill(AlignedArray<T>& a, std::size_t n, const std::byte*& at) {
    if (n > 0) std::memcpy(a.data(), at, n * sizeof(T));  // an empty set has no arrays at all
    at += n * sizeof(T);
  }
  template <class T>
  static void fill(AppliedVectors<T>& v, std::size_t n, std::size_t capacity, const std::byte*& at) {
    v.ensure(capacity);
    for (auto& a : v.arrays_) fill(a, n, at);
    v.active_ = true;
  }

  template <class T>
  static void fill(BodyParameters<T>& p, std::size_t n, std::size_t capacity, std::uint8_t flags,
                   const std::byte*& at) {
    for (const auto& [flag, kind] : kParameterFlags) {
      if (!(flags & flag)) continue;
      p.ensure(capacity);
      AlignedArray<T>& a = p.arrays_[int(kind)];
      fill(a, n, at);
      p.used_[int(kind)] = true;
      p.largest_[int(kind)] = std::abs(BodyParameters<T>::default_of(kind));
      for (std::size_t i = 0; i < n; ++i) p.largest_[int(kind)] = std::max(p.largest_[int(kind)], std::abs(a[i]));
    }
  }

  template <class T>
  static ParticleSet<T> particles(std::size_t n, const std::byte*& at) {
    ParticleSet<T> b;
    b.reserve(n);
    for (AlignedArray<T>* a : {&b.px_, &b.py_, &b.pz_, &b.vx_, &b.vy_, &b.vz_, &b.inv_mass_}) fill(*a, n, at);
    b.size_ = n;
    return b;
  }
  template <class T>
  static void finish(ParticleSet<T>& b, std::uint8_t flags, const std::byte*& at) {
    if (flags & kForces) fill(b.applied_, b.size_, b.capacity(), at);
    b.keep_forces_ = (flags & kKeepForces) != 0;
  }
  template <class T>
  static void finish_parameters(ParticleSet<T>& b, std::uint8_t flags, const std::byte*& at) {
    fill(b.params_, b.size_, b.capacity(), flags, at);
  }
  template <class T>
  static RigidBodySet<T> rigid(std::size_t n, std::uint8_t flags, const std::byte*& at) {
    RigidBodySet<T> b;
    b.reserve(n);
    ParticleSet<T>& c = b.centers_;
    for (AlignedArray<T>* a : {&c.px_, &c.py_, &c.pz_, &c.vx_, &c.vy_, &c.vz_, &c.inv_mass_}) fill(*a, n, at);
    c.size_ = n;
    for (auto& a : b.q_) fill(a, n, at);
    for (auto& a : b.l_) fill(a, n, at);
    for (auto& a : b.inv_inertia_) fill(a, n, at);
    finish(c, flags, at);
    if (flags & kTorques) fill(b.torques_, n, c.capacity(), at);
    finish_parameters(c, flags, at);
    return b;
  }
};

namespace {

template <class T, class Set>
CheckpointWriter::Record make_record(const Set& bodies, const Stepper<T>& stepper, SetKind kind) {
  using Codec = detail::CheckpointCodec;
  std::vector<const T*> arrays;
  Codec::arrays(bodies, arrays);
  const AppliedVectors<T>& forces = Codec::forces(bodies);
  const AppliedVectors<T>* torques = Codec::torques(bodies);
  std::uint8_t flags = bodies.keeps_forces() ? kKeepForces : 0;
  if (forces.active()) flags |= kForces, Codec::applied(forces, arrays);
  if (torques != nullptr && torques->active()) flags |= kTorques, Codec::applied(*torques, arrays);
  Codec::parameters(Codec::parameters(bodies), kind, flags, arrays);
  // A call that ended leaves its fields behind, unread: a record holds them only while one
  // goes on, so that equal states make equal records. One the set has changed since (as
  // Stepper::advance_to would judge it) would not go on: neither does the record's.
  const AdaptiveContinuation& live = StepperAccess<T>::continuation(stepper);
  bool goes_on = live.active;
  if constexpr (std::is_same_v<Set, ParticleSet<T>>) {
    goes_on = goes_on && (!live.inputs || *live.inputs == stage_inputs_digest(bodies));
  }
  const AdaptiveContinuation cont = goes_on ? live : AdaptiveContinuation{};
  if (cont.active && cont.kept_scale > 0) {
    flags |= kKeptStage;
    for (const T* a : StepperAccess<T>::staged(stepper)->first_stage()) arrays.push_back(a);
  }

  CheckpointWriter::Record r{};
  std::byte* h = r.header.data();
  const StepperOptions& o = stepper.options();
  const StepperClock clock = stepper.clock();
  put(h + rec::kind, std::uint8_t(kind));
  put(h + rec::scalar, std::uint8_t(sizeof(T)));
  put(h + rec::flags, flags);
  put(h + rec::guard, std::uint8_t(o.guard));
  put(h + rec::bodies, std::uint64_t(bodies.size()));
  put(h + rec::model, stepper.forces().fingerprint());
  put(h + rec::method, method_fingerprint(stepper.method()));
  put(h + rec::origin, clock.origin);
  put(h + rec::steps, clock.steps);
  put(h + rec::h, clock.h);
  put(h + rec::proposed, clock.proposed_step);
  put(h + rec::max_speed, o.max_speed);
  put(h + rec::max_angular, o.max_angular_speed);
  const std::string_view name = stepper.method().name;
  std::memcpy(h + rec::name, name.data(), std::min(name.size(), kMethodNameBytes - 1));
  put(h + rec::continues, std::uint8_t(cont.active));
  put(h + rec::rejected, std::uint8_t(cont.controller.rejected));
  put(h + rec::relaxed, std::uint8_t(o.relaxed_fma));
  put(h + rec::quaternions, std::uint8_t(o.renormalize_quaternions ? 1 : 2));
  const ImplicitSolves solves = implicit_solves(stepper);
  put(h + rec::implicit_tolerance, solves.tolerance);
  put(h + rec::implicit_iterations, solves.iterations);
  put(h + rec::preconditioner, solves.multigrid);
  for (const auto& [at, value] : {std::pair{rec::t_end, cont.t_end}, {rec::rtol, cont.rtol}, {rec::atol, cont.atol},
                                  {rec::max_step, cont.max_step}, {rec::next_h, cont.h},
                                  {rec::err_prev, cont.controller.err_prev}, {rec::kept_scale, cont.kept_scale}}) {
    put(h + at, value);
  }
  put(h + rec::crc, crc_of(h, rec::crc));
  for (const T* a : arrays) r.arrays.emplace_back(reinterpret_cast<const std::byte*>(a), bodies.size() * sizeof(T));
  return r;
}

// Appends to a byte vector.
struct VectorSink {
  std::vector<std::byte>& out;
  void operator()(std::span<const std::byte> bytes) { out.insert(out.end(), bytes.begin(), bytes.end()); }
};

struct FileSink {
  WholeFile& file;
  void operator()(std::span<const std::byte> bytes) { file.write(bytes); }
};

}  // namespace

template <class T>
void CheckpointWriter::add(const ParticleSet<T>& bodies, const Stepper<T>& stepper) {
  records_.push_back(make_record(bodies, stepper, SetKind::particles));
}

template <class T>
void CheckpointWriter::add(const RigidBodySet<T>& bodies, const Stepper<T>& stepper) {
  records_.push_back(make_record(bodies, stepper, SetKind::rigid));
}

std::size_t CheckpointWriter::size() const {
  std::size_t bytes = kCheckpointHeaderBytes + user_.size() + kTrailerBytes;
  for (const Record& r : records_) {
    bytes += r.header.size();
    for (const auto& a : r.arrays) bytes += a.size();
  }
  return bytes;
}

// Every byte through `sink` in order, the running CRC-32C last.
template <class Sink>
std::uint32_t CheckpointWriter::emit(Sink& sink) const {
  std::array<std::byte, kCheckpointHeaderBytes> h{};
  std::memcpy(h.data(), kMagic, sizeof kMagic);
  put(h.data() + head::version, kCheckpointVersion);
  put(h.data() + head::records, std::uint32_t(records_.size()));
  put(h.data() + head::total, std::uint64_t(size()));
  put(h.data() + head::user, std::uint64_t(user_.size()));
  put(h.data() + head::crc, crc_of(h.data(), head::crc));
  std::uint32_t crc = 0;
  const auto out = [&](std::span<const std::byte> bytes) {
    crc = crc32c(bytes, crc);
    sink(bytes);
  };
  out(h);
  for (const Record& r : records_) {
    out(r.header);
    for (const auto& a : r.arrays) out(a);
  }
  out(user_);
  std::array<std::byte, kTrailerBytes> trailer;
  put(trailer.data(), crc);
  sink(trailer);
  return crc;
}

std::uint32_t CheckpointWriter::crc() const {
  auto nowhere = [](std::span<const std::byte>) {};
  return emit(nowhere);
}

std::uint32_t CheckpointWriter::digest() const {
  std::uint32_t c = 0;
  for (const Record& r : records_) {
    c = crc32c(std::span<const std::byte>(r.header).first(rec::crc), c);
    for (const auto& a : r.arrays) c = crc32c(a, c);
  }
  return crc32c(user_, c);
}

std::vector<std::byte> CheckpointWriter::bytes() const {
  std::vector<std::byte> out;
  out.reserve(size());
  VectorSink sink{out};
  emit(sink);
  return out;
}

void CheckpointWriter::save(const std::filesystem::path& path) const {
  WholeFile file(path, "checkpoint");
  FileSink sink{file};
  emit(sink);
  file.commit();
}

namespace {

[[noreturn]] void refuse(const std::string& why) { throw Error("not a usable checkpoint: " + why); }

std::size_t arrays_of(SetKind kind, std::uint8_t flags) {
  std::size_t n = kind == SetKind::particles ? kParticleArrays : kRigidArrays;
  for (const Flags f : {kForces, kTorques, kKeptStage}) n += flags & f ? 3 : 0;
  for (const auto& p : kParameterFlags) n += flags & p.first ? 1 : 0;
  return n;
}

// Checks one record header at `at` (with `left` bytes from there to the user data) and
// returns its length, header included.
std::size_t check_record_header(const std::byte* h, std::size_t left, std::size_t index) {
  const std::string which = "record " + std::to_string(index);
  if (left < kCheckpointRecordBytes) refuse(which + " is cut short");
  if (get<std::uint32_t>(h + rec::crc) != crc_of(h, rec::crc)) refuse(which + ": its header is damaged (checksum)");
  const auto kind = SetKind(get<std::uint8_t>(h + rec::kind));
  const auto scalar = get<std::uint8_t>(h + rec::scalar), flags = get<std::uint8_t>(h + rec::flags);
  const bool known = (kind == SetKind::particles || kind == SetKind::rigid) && (scalar == 4 || scalar == 8) &&
                     flags < 128 && !(kind == SetKind::particles && (flags & (kTorques | kAngularDamping))) &&
                     !(kind == SetKind::rigid && (flags & kKeptStage)) && get<std::uint8_t>(h + rec::guard) < 3 &&
                     get<std::uint8_t>(h + rec::continues) < 2 && get<std::uint8_t>(h + rec::rejected) < 2 &&
                     get<std::uint8_t>(h + rec::relaxed) < 2 && get<std::uint8_t>(h + rec::quaternions) < 3;
  if (!known) refuse(which + ": unknown kind, precision or flags");
  const std::uint64_t bodies = get<std::uint64_t>(h + rec::bodies);
  const std::size_t per_body = arrays_of(kind, flags) * scalar;
  const std::size_t room = left - kCheckpointRecordBytes;
  if (bodies > room / per_body) {
    refuse(which + " counts " + std::to_string(bodies) + " bodies (" + std::to_string(per_body) +
           " bytes each), more than its " + std::to_string(room) + " bytes of data can hold");
  }
  return kCheckpointRecordBytes + std::size_t(bodies) * per_body;
}

}  // namespace

CheckpointReader::CheckpointReader(std::vector<std::byte> data) : data_(std::move(data)) {
  const std::size_t size = data_.size();
  const std::byte* d = data_.data();
  if (size == 0) refuse("the file is empty");
  if (size < kCheckpointHeaderBytes + kTrailerBytes || std::memcmp(d, kMagic, sizeof kMagic) != 0) {
    refuse(size < sizeof kMagic || std::memcmp(d, kMagic, sizeof kMagic) != 0
               ? "not a kinema checkpoint (no \"kinemaCK\" at its start)"
               : std::to_string(size) + " bytes, too short for a checkpoint");
  }
  if (get<std::uint32_t>(d + head::crc) != crc_of(d, head::crc)) refuse("its header is damaged (checksum)");
  const auto version = get<std::uint32_t>(d + head::version);
  if (version != kCheckpointVersion) {
    refuse("version " + std::to_string(version) + "; this kinema reads version " + std::to_string(kCheckpointVersion));
  }
  const auto total = get<std::uint64_t>(d + head::total), user = get<std::uint64_t>(d + head::user);
  if (total != size) {
    refuse((total > size ? "truncated: " : "longer than it says: ") + std::to_string(size) +
           " bytes where its header says " + std::to_string(total));
  }
  if (user > size - kCheckpointHeaderBytes - kTrailerBytes) refuse("its user data is longer than the file");
  const std::size_t end = size - kTrailerBytes - std::size_t(user);
  std::size_t at = kCheckpointHeaderBytes;
  const auto count = get<std::uint32_t>(d + head::records);
  if (count > (end - at) / kCheckpointRecordBytes) refuse("it counts more records than its data holds");
  for (std::uint32_t k = 0; k < count; ++k) {
    const std::size_t length = check_record_header(d + at, end - at, k);
    records_.push_back({at, at + kCheckpointRecordBytes, get<std::uint64_t>(d + at + rec::bodies)});
    at += length;
  }
  if (at != end) refuse("its records and user data do not add up to its length");
  if (get<std::uint32_t>(d + end + user) != crc_of(d, size - kTrailerBytes)) refuse("its data is damaged (checksum)");
  user_offset_ = end, user_bytes_ = std::size_t(user);
}

CheckpointReader CheckpointReader::load(const std::filesystem::path& path, std::size_t max_bytes) {
  std::vector<std::byte> data = read_regular_file(path, max_bytes, "checkpoint");
  try {
    return CheckpointReader(std::move(data));
  } catch (const Error& e) {
    throw Error(printable(path.string()) + ": " + e.what());
  }
}

std::span<const std::byte> CheckpointReader::user_data() const { return {data_.data() + user_offset_, user_bytes_}; }

template <class T>
void CheckpointReader::check_record(std::size_t k, bool rigid, const Stepper<T>& stepper) const {
  if (k >= records_.size()) {
    throw Error("checkpoint: no record " + std::to_string(k) + " (it has " + std::to_string(records_.size()) + ")");
  }
  const std::byte* h = data_.data() + records_[k].header;
  const std::string which = "checkpoint record " + std::to_string(k);
  const auto kind = SetKind(get<std::uint8_t>(h + rec::kind));
  if ((kind == SetKind::rigid) != rigid) {
    throw Error(which + " holds " + (rigid ? "particles" : "rigid bodies") + ", not " + (rigid ? "rigid bodies" : "particles"));
  }
  const std::size_t scalar = get<std::uint8_t>(h + rec::scalar);
  if (scalar != sizeof(T)) throw Error(which + " was taken in " + precision_of(scalar) + ", not " + precision_of(sizeof(T)));
  char name[kMethodNameBytes + 1] = {};
  std::memcpy(name, h + rec::name, kMethodNameBytes - 1);
  if (get<std::uint64_t>(h + rec::method) != method_fingerprint(stepper.method())) {
    throw Error(which + " was taken with method " + printable(name) + ", not " + std::string(stepper.method().name));
  }
  if (get<std::uint64_t>(h + rec::model) != stepper.forces().fingerprint()) {
    throw Error(which + " was taken under another force model (its terms or their parameters differ)");
  }
  const StepperOptions& o = stepper.options();
  const auto guard = get<std::uint8_t>(h + rec::guard);
  const bool same_clamp = o.guard != FiniteGuard::clamp || (get<double>(h + rec::max_speed) == o.max_speed &&
                                                           get<double>(h + rec::max_angular) == o.max_angular_speed);
  if (guard != std::uint8_t(o.guard) || !same_clamp) {
    throw Error(which + " was taken under the finiteness guard " + std::string(guard_name(guard)) +
                " with other settings than this stepper's (" + std::string(guard_name(std::uint8_t(o.guard))) + ")");
  }
  if ((get<std::uint8_t>(h + rec::relaxed) != 0) != o.relaxed_fma) {
    throw Error(which + " was taken " + (o.relaxed_fma ? "without" : "with") +
                " relaxed_fma, which changes the last bits on the scalar and SSE2 paths");
  }
  const auto quaternions = get<std::uint8_t>(h + rec::quaternions);
  if (kind == SetKind::rigid && quaternions != 0 && (quaternions == 1) != o.renormalize_quaternions) {
    throw Error(which + " was taken " + (o.renormalize_quaternions ? "without" : "with") +
                " renormalize_quaternions, which changes the rigid steps' bits");
  }
  const ImplicitSolves solves = implicit_solves(stepper);
  const auto tolerance = get<double>(h + rec::implicit_tolerance);
  const auto iterations = get<std::int32_t>(h + rec::implicit_iterations);
  if (solves.iterations > 0 && tolerance == 0 && iterations == 0) {
    throw Error(which + " was taken before checkpoints kept an implicit method's solve options: "
                        "it cannot say which its steps took");
  }
  if (tolerance != solves.tolerance || iterations != solves.iterations) {
    char text[200];
    std::snprintf(text, sizeof text,
                  " was taken with implicit solves to %g within %d iterations, not this stepper's %g within %d: "
                  "the steps would differ",
                  tolerance, int(iterations), solves.tolerance, int(solves.iterations));
    throw Error(which + text);
  }
  const auto preconditioner = get<std::uint8_t>(h + rec::preconditioner);
  if (preconditioner > 2) {
    throw Error(which + " names an unknown preconditioner (" + std::to_string(preconditioner) + ")");
  }
  const bool multigrid = preconditioner == 2;  // 0: a record from before it was kept, Jacobi's
  if (solves.iterations > 0 && multigrid != (solves.multigrid == 2)) {
    throw Error(which + " was taken with implicit solves preconditioned by " + (multigrid ? "multigrid" : "Jacobi") +
                ", not this stepper's " + (multigrid ? "Jacobi" : "multigrid") +
                ": the steps would differ (StepperOptions::implicit_preconditioner, kinema run "
                "--implicit-preconditioner " + (multigrid ? "multigrid" : "jacobi") + ")");
  }
}

StepperClock CheckpointReader::clock(std::size_t k) const {
  if (k >= records_.size()) throw Error("checkpoint: no record " + std::to_string(k));
  const std::byte* h = data_.data() + records_[k].header;
  return {get<double>(h + rec::origin), get<std::uint64_t>(h + rec::steps), get<double>(h + rec::h),
          get<double>(h + rec::proposed)};
}

namespace {

// A checksum guards against damage, not against a file made to pass it: the state must be
// finite and the inverse masses and moments finite and >= 0, as a set's setters keep them.
void check_inverse(const char* name, std::size_t k, const auto* values, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    if (!(values[i] >= 0 && values[i] <= std::numeric_limits<std::decay_t<decltype(values[i])>>::max())) {
      throw Error("checkpoint record " + std::to_string(k) + ": body " + std::to_string(i) + "'s " + name +
                  " is not finite and >= 0");
    }
  }
}

// Gravity factors finite, damping rates finite and >= 0, as the setters keep them.
template <class T>
void check_parameters(const BodyParameters<T>& p, std::size_t k, std::size_t n) {
  for (BodyParameter kind : {BodyParameter::linear_damping, BodyParameter::angular_damping}) {
    if (p.used(kind)) check_inverse("damping rate", k, p.data(kind), n);
  }
  if (!p.used(BodyParameter::gravity_factor)) return;
  const T* factor = p.data(BodyParameter::gravity_factor);
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(factor[i])) {
      throw Error("checkpoint record " + std::to_string(k) + ": body " + std::to_string(i) + "'s gravity factor is not finite");
    }
  }
}

// Orientations a step can normalize: |q|^2 between the square root of T's smallest normal
// number and of its largest (near 1 as the setters and steps leave it, or drifted under
// renormalize_quaternions = false). A zero, vanishing or overflowing one makes the next step NaN.
template <class T>
void check_quaternions(const RigidBodySet<T>& b, std::size_t k) {
  const double least = std::sqrt(double(std::numeric_limits<T>::min())), most = std::sqrt(double(std::numeric_limits<T>::max()));
  for (std::size_t i = 0; i < b.size(); ++i) {
    double norm2 = 0;
    for (int c = 0; c < 4; ++c) norm2 += double(b.q(c)[i]) * double(b.q(c)[i]);
    if (!(norm2 >= least && norm2 <= most)) {
      throw Error("checkpoint record " + std::to_string(k) + ": body " + std::to_string(i) +
                  "'s orientation quaternion is zero or too small or large to normalize");
    }
  }
}

// Applied forces or torques (data(d): component d, or nullptr when none), which the setters
// keep finite.
template <class Data>
void check_applied(Data data, const char* what, std::size_t k, std::size_t n) {
  for (int d = 0; d < 3 && data(0) != nullptr; ++d) {
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(data(d)[i])) {
        throw Error("checkpoint record " + std::to_string(k) + ": body " + std::to_string(i) + "'s applied " + what +
                    " is not finite");
      }
    }
  }
}

template <class Set>
void check_values(const Set& b, std::size_t k) {
  check_parameters(b.parameters(), k, b.size());
  if constexpr (requires { b.centers(); }) {
    check_applied([&](int d) { return b.centers().applied_force_data(d); }, "force", k, b.size());
    check_applied([&](int d) { return b.applied_torque_data(d); }, "torque", k, b.size());
  } else {
    check_applied([&](int d) { return b.applied_force_data(d); }, "force", k, b.size());
  }
  if (const auto bad = first_non_finite(b)) {
    throw Error("checkpoint record " + std::to_string(k) + ": body " + std::to_string(bad->body) + "'s " +
                bad->field + " is not finite");
  }
  if constexpr (requires { b.centers(); }) {
    check_inverse("inverse mass", k, b.centers().inv_mass(), b.size());
    for (int d = 0; d < 3; ++d) check_inverse("inverse moment", k, b.inv_inertia(d), b.size());
    check_quaternions(b, k);
  } else {
    check_inverse("inverse mass", k, b.inv_mass(), b.size());
  }
}

}  // namespace

template <class T>
ParticleSet<T> CheckpointReader::particles(std::size_t k, const Stepper<T>& stepper) const {
  check_record(k, false, stepper);
  const std::uint8_t flags = get<std::uint8_t>(data_.data() + records_[k].header + rec::flags);
  const std::byte* at = data_.data() + records_[k].arrays;
  ParticleSet<T> b = detail::CheckpointCodec::particles<T>(records_[k].bodies, at);
  detail::CheckpointCodec::finish(b, flags, at);
  detail::CheckpointCodec::finish_parameters(b, flags, at);
  check_values(b, k);
  return b;
}

template <class T>
RigidBodySet<T> CheckpointReader::rigid_bodies(std::size_t k, const Stepper<T>& stepper) const {
  check_record(k, true, stepper);
  const std::uint8_t flags = get<std::uint8_t>(data_.data() + records_[k].header + rec::flags);
  const std::byte* at = data_.data() + records_[k].arrays;
  RigidBodySet<T> b = detail::CheckpointCodec::rigid<T>(records_[k].bodies, flags, at);
  check_values(b, k);
  return b;
}

namespace {

AdaptiveContinuation continuation_in(const std::byte* h) {
  AdaptiveContinuation c;
  c.active = get<std::uint8_t>(h + rec::continues) != 0;
  c.controller.rejected = get<std::uint8_t>(h + rec::rejected) != 0;
  c.t_end = get<double>(h + rec::t_end), c.rtol = get<double>(h + rec::rtol), c.atol = get<double>(h + rec::atol);
  c.max_step = get<double>(h + rec::max_step), c.h = get<double>(h + rec::next_h);
  c.controller.err_prev = get<double>(h + rec::err_prev), c.kept_scale = get<double>(h + rec::kept_scale);
  return c;
}

// What a controller can have left: a finite end (of either sign, as the clock), finite
// tolerances and sizes (the cap may be infinite), and a kept stage exactly when it says it
// kept one.
void check_continuation(const AdaptiveContinuation& c, bool kept, std::size_t k) {
  const auto finite = [](double x) { return std::isfinite(x) && x >= 0; };
  const bool valid = !c.active ? !kept
                               : std::isfinite(c.t_end) && finite(c.rtol) && finite(c.atol) && c.max_step > 0 && c.h > 0 &&
                                     finite(c.h) && c.controller.err_prev > 0 && finite(c.controller.err_prev) &&
                                     finite(c.kept_scale) && kept == (c.kept_scale > 0);
  if (!valid) throw Error("checkpoint record " + std::to_string(k) + ": its error control's state is not one it can have");
}

}  // namespace

template <class T>
const std::byte* CheckpointReader::kept_stage(std::size_t k) const {
  const std::uint8_t flags = get<std::uint8_t>(data_.data() + records_[k].header + rec::flags);
  if (!(flags & kKeptStage)) return nullptr;
  const std::size_t before = arrays_of(SetKind::particles, flags) - 3;  // the kept stage's arrays come last
  return data_.data() + records_[k].arrays + before * records_[k].bodies * sizeof(T);
}

template <class T>
void CheckpointReader::restore_stepper(std::size_t k, Stepper<T>& io_stepper) const {
  if (k >= records_.size()) throw Error("checkpoint: no record " + std::to_string(k));
  const std::byte* h = data_.data() + records_[k].header;
  check_record(k, SetKind(get<std::uint8_t>(h + rec::kind)) == SetKind::rigid, io_stepper);
  AdaptiveContinuation cont = continuation_in(h);
  cont.bodies = records_[k].bodies;  // the set the record holds is the set it goes on with
  const std::byte* stage = kept_stage<T>(k);
  check_continuation(cont, stage != nullptr, k);
  StagedPath<T>* staged = StepperAccess<T>::staged(io_stepper);
  if (stage != nullptr && staged == nullptr) {
    throw Error("checkpoint record " + std::to_string(k) + ": this stepper keeps no stages");
  }
  const std::size_t n = records_[k].bodies;
  for (std::size_t i = 0; stage != nullptr && i < 3 * n; ++i) {
    if (!std::isfinite(get<T>(stage + i * sizeof(T)))) {
      throw Error("checkpoint record " + std::to_string(k) + ": its kept stage is not finite");
    }
  }
  // Everything that can throw (the clock's values, the stage's memory) before anything changes.
  const std::array<T*, 3> into = stage != nullptr ? staged->first_stage_for(padded_count<T>(n)) : std::array<T*, 3>{};
  io_stepper.set_clock(clock(k));
  for (int d = 0; d < 3 && stage != nullptr && n > 0; ++d) std::memcpy(into[d], stage + d * n * sizeof(T), n * sizeof(T));
  StepperAccess<T>::continuation(io_stepper) = cont;
}

template <class T>
void CheckpointReader::restore(std::size_t k, ParticleSet<T>& io_bodies, Stepper<T>& io_stepper) const {
  ParticleSet<T> restored = particles(k, io_stepper);
  restore_stepper(k, io_stepper);  // throws before the set changes
  io_bodies = std::move(restored);
  AdaptiveContinuation& cont = StepperAccess<T>::continuation(io_stepper);
  if (cont.active) cont.inputs = stage_inputs_digest(io_bodies);  // its set as the record holds it
}

template <class T>
void CheckpointReader::restore(std::size_t k, RigidBodySet<T>& io_bodies, Stepper<T>& io_stepper) const {
  RigidBodySet<T> restored = rigid_bodies(k, io_stepper);
  restore_stepper(k, io_stepper);
  io_bodies = std::move(restored);
}

template void CheckpointWriter::add(const ParticleSet<float>&, const Stepper<float>&);
template void CheckpointWriter::add(const ParticleSet<double>&, const Stepper<double>&);
template void CheckpointWriter::add(const RigidBodySet<float>&, const Stepper<float>&);
template void CheckpointWriter::add(const RigidBodySet<double>&, const Stepper<double>&);
template void CheckpointReader::restore(std::size_t, ParticleSet<float>&, Stepper<float>&) const;
template void CheckpointReader::restore(std::size_t, ParticleSet<double>&, Stepper<double>&) const;
template void CheckpointReader::restore(std::size_t, RigidBodySet<float>&, Stepper<float>&) const;
template void CheckpointReader::restore(std::size_t, RigidBodySet<double>&, Stepper<double>&) const;
template void CheckpointReader::restore_stepper(std::size_t, Stepper<float>&) const;
template void CheckpointReader::restore_stepper(std::size_t, Stepper<double>&) const;
template ParticleSet<float> CheckpointReader::particles(std::size_t, const Stepper<float>&) const;
template ParticleSet<double> CheckpointReader::particles(std::size_t, const Stepper<double>&) const;
template RigidBodySet<float> CheckpointReader::rigid_bodies(std::size_t, const Stepper<float>&) const;
template RigidBodySet<double> CheckpointReader::rigid_bodies(std::size_t, const Stepper<double>&) const;

}  // namespace kinema
