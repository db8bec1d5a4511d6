#pragma once
// The forces rigid bodies feel at body points: point springs (each body's point held to a
// world anchor) and body springs (points of two bodies). The rigid path evaluates them per
// block between a stage's state and its rates, adding forces and torques where the callbacks
// add theirs. Scalar code in T, compiled once without contraction: the same bits on every
// instruction set. Each body sums its springs in model order, and a body spring's force on
// j is the exact negation of its force on i.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kinema/bodies.hpp"
#include "kinema/forces.hpp"

namespace kinema {

// Every body's state at one stage, and the force and torque the stage's terms add to.
template <class T>
struct RigidStage {
  const T* x[3];
  const T* v[3];
  const T* q[4];
  const T* omega[3];
  T* force[3];
  T* torque[3];
};

// Throws kinema::Error when body springs reaching `covered` bodies (the largest index + 1)
// meet a set of fewer.
void check_body_springs_reach(std::size_t covered, std::size_t bodies);

template <class T>
class RigidCoupling {
 public:
  // The model's point springs and body springs in T. Throws kinema::Error naming a
  // parameter that overflows T.
  explicit RigidCoupling(const ForceModel<T>& forces);

  bool empty() const { return points_.empty() && ends_.empty(); }
  bool coupled() const { return !ends_.empty(); }  // body springs read other bodies' state
  // Throws kinema::Error when a body spring joins a body past `bodies`.
  void check_reach(std::size_t bodies) const;
  std::size_t spring_count() const { return links_.size(); }
  // Body springs [begin, end) at stage state `s`, each once, into their own scratch: before
  // add() for any body at that stage, once every body's stage state is written.
  void evaluate_springs(const RigidStage<T>& s, std::size_t begin, std::size_t end);
  // Adds the forces and torques on bodies [begin, end) at stage state `s`: the point springs',
  // and each body's body springs from evaluate_springs, in model order.
  void add(const RigidStage<T>& s, std::size_t begin, std::size_t end) const;

 private:
  struct Point {
    T point[3], anchor[3], k, damping;
  };
  struct Link {
    std::uint32_t i, j;
    T point_i[3], point_j[3], rest, k, damping;
  };
  // One end of a body spring, sorted by body then spring: a body's ends are a run.
  struct End {
    std::uint32_t body, link;
  };
  // A body spring's force on end i and the torques on both ends; on end j the force is -force.
  struct Pull {
    T force[3], torque_i[3], torque_j[3];
  };
  Pull pull(const RigidStage<T>& s, const Link& l) const;

  std::vector<Point> points_;
  std::vector<Link> links_;
  std::vector<Pull> pulls_;  // each spring's, at the stage evaluate_springs saw last
  std::vector<End> ends_;
  std::size_t covered_ = 0;  // the largest body index a spring joins, plus 1
};

// The potential energy of the point springs and body springs, in double: 1/2 k |P - anchor|^2
// and 1/2 k (|P_i - P_j| - rest)^2 over bodies with inv_mass != 0 (a body spring counts when
// either end is). kinema::Error as check_body_springs_reach for a spring past the set.
template <class T>
double rigid_coupling_potential(const RigidBodySet<T>& bodies, const ForceModel<T>& forces);

extern template class RigidCoupling<float>;
extern template class RigidCoupling<double>;

}  // namespace kinema
