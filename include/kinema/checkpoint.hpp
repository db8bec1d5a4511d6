#pragma once
// Checkpoints: body sets and their steppers' clocks as bytes or a file, and back, so that a
// run resumes bit for bit (in another process, on any thread count and instruction set).
//
//   CheckpointWriter out;
//   out.add(bodies, stepper);              // any number of sets, particles or rigid bodies
//   out.save("world.ckpt");                // written whole (kinema/files.hpp)
//   ...
//   const CheckpointReader in = CheckpointReader::load("world.ckpt");
//   in.restore(0, bodies, stepper);        // record 0, checked against this stepper
//
// What a record holds: every real body's state as its set stores it (positions, velocities,
// inverse mass; rigid bodies also orientation, angular momentum, inverse moments), the
// applied forces and torques when the set has them and whether it keeps them, the per-body
// parameters it has set (gravity factors, damping rates; a particle record leaves out angular
// damping), the stepper's clock exactly (Stepper::clock) and the step advance_to last
// proposed, and what the record
// may only be restored under: the precision, the kind of set, the method, the force model's
// fingerprint (ForceModel::fingerprint), the finiteness guard's settings, relaxed_fma, for a
// rigid set renormalize_quaternions (records from before it was kept restore under either), and
// for an implicit method its solves' tolerance and iteration cap (as they run: a 0
// tolerance is the precision's default, so naming the default restores too);
// and when an advance_to call was stopped early (AdaptiveStats::stopped), what its next call
// goes on from: the controller's state and the first-same-as-last stage. Stepping the restored set
// with the same calls then gives the same bits as never stopping. (A call that ran to its
// end leaves nothing: the next starts afresh from Tolerances::initial_step, for which
// Stepper::clock().proposed_step is kept.)
//
// Version 1 layout, little-endian (x86-64): a 48-byte header ("kinemaCK", the version, the
// record count, the total length, the user data's length, the header's CRC-32C); each record:
// a 192-byte header with its own CRC-32C, then n values per array (no padding); the user
// data; the CRC-32C of every byte before it. Loading checks the header, every record header
// and every length against the data's length, and the checksum, before it allocates
// anything: a truncated, damaged or foreign checkpoint is refused with one line (a
// kinema::Error) and nothing changes.

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/stepper.hpp"

namespace kinema {

inline constexpr std::uint32_t kCheckpointVersion = 1;
inline constexpr std::size_t kCheckpointHeaderBytes = 48, kCheckpointRecordBytes = 192;

// Collects sets and their steppers, then writes them at once. It keeps views of the sets'
// arrays, not copies: write (bytes, save) before the sets change.
class CheckpointWriter {
 public:
  template <class T>
  void add(const ParticleSet<T>& bodies, const Stepper<T>& stepper);
  template <class T>
  void add(const RigidBodySet<T>& bodies, const Stepper<T>& stepper);
  // The application's own bytes (what it needs to resume: progress, counters), kept as given.
  void set_user_data(std::vector<std::byte> data) { user_ = std::move(data); }

  std::size_t size() const;  // bytes, trailer included
  // The CRC-32C the checkpoint ends with, computed without writing it. Each header carries a
  // checksum of its own, so this one does not depend on what a header holds (a record's clock,
  // method and options): compare states with digest().
  std::uint32_t crc() const;
  // A CRC-32C of what the checkpoint holds, its checksums left out: every record's header (the
  // kind, precision, clock, method and options) and arrays, and the user data. Equal bits,
  // equal values; a record of another clock or state, another value (but for 2^-32 chances).
  std::uint32_t digest() const;
  std::vector<std::byte> bytes() const;
  void save(const std::filesystem::path& path) const;  // as a WholeFile ("checkpoint")

  struct Record {
    std::array<std::byte, kCheckpointRecordBytes> header;
    std::vector<std::span<const std::byte>> arrays;
  };

 private:
  template <class Sink>
  std::uint32_t emit(Sink& sink) const;  // returns the CRC-32C it ends with

  std::vector<Record> records_;
  std::vector<std::byte> user_;
};

// A checkpoint checked whole on construction (kinema::Error, one line, for anything that is
// not an intact checkpoint of this version).
class CheckpointReader {
 public:
  explicit CheckpointReader(std::vector<std::byte> data);
  // Reads a regular file (kinema/files.hpp) of at most max_bytes.
  static CheckpointReader load(const std::filesystem::path& path,
                               std::size_t max_bytes = std::size_t(1) << 40);

  std::size_t records() const { return records_.size(); }
  std::span<const std::byte> user_data() const;

  // Record k into the set and the stepper, all or nothing: kinema::Error (nothing changed)
  // when k is not a record of that kind and precision, or was taken under another method,
  // force model or guard than the stepper's.
  template <class T>
  void restore(std::size_t k, ParticleSet<T>& io_bodies, Stepper<T>& io_stepper) const;
  template <class T>
  void restore(std::size_t k, RigidBodySet<T>& io_bodies, Stepper<T>& io_stepper) const;
  // The parts, for restoring several records all or nothing (World::restore): the set
  // decoded and checked against the stepper, and the clock to give the stepper.
  template <class T>
  ParticleSet<T> particles(std::size_t k, const Stepper<T>& stepper) const;
  template <class T>
  RigidBodySet<T> rigid_bodies(std::size_t k, const Stepper<T>& stepper) const;
  StepperClock clock(std::size_t k) const;
  // Record k's clock and continuation into `stepper` (checked as restore checks them; nothing
  // changes when it throws).
  template <class T>
  void restore_stepper(std::size_t k, Stepper<T>& io_stepper) const;

  struct Record {
    std::size_t header;  // offset of the record header
    std::size_t arrays;  // offset of its first array
    std::uint64_t bodies;
  };

 private:
  template <class T>
  void check_record(std::size_t k, bool rigid, const Stepper<T>& stepper) const;
  template <class T>
  const std::byte* kept_stage(std::size_t k) const;  // nullptr when record k keeps none

  std::vector<std::byte> data_;
  std::vector<Record> records_;
  std::size_t user_offset_ = 0, user_bytes_ = 0;
};

extern template void CheckpointWriter::add(const ParticleSet<float>&, const Stepper<float>&);
extern template void CheckpointWriter::add(const ParticleSet<double>&, const Stepper<double>&);
extern template void CheckpointWriter::add(const RigidBodySet<float>&, const Stepper<float>&);
extern template void CheckpointWriter::add(const RigidBodySet<double>&, const Stepper<double>&);
extern template void CheckpointReader::restore(std::size_t, ParticleSet<float>&, Stepper<float>&) const;
extern template void CheckpointReader::restore(std::size_t, ParticleSet<double>&, Stepper<double>&) const;
extern template void CheckpointReader::restore(std::size_t, RigidBodySet<float>&, Stepper<float>&) const;
extern template void CheckpointReader::restore(std::size_t, RigidBodySet<double>&, Stepper<double>&) const;
extern template void CheckpointReader::restore_stepper(std::size_t, Stepper<float>&) const;
extern template void CheckpointReader::restore_stepper(std::size_t, Stepper<double>&) const;
extern template ParticleSet<float> CheckpointReader::particles(std::size_t, const Stepper<float>&) const;
extern template ParticleSet<double> CheckpointReader::particles(std::size_t, const Stepper<double>&) const;
extern template RigidBodySet<float> CheckpointReader::rigid_bodies(std::size_t, const Stepper<float>&) const;
extern template RigidBodySet<double> CheckpointReader::rigid_bodies(std::size_t, const Stepper<double>&) const;

}  // namespace kinema
