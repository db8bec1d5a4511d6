#include "kinema/forces.hpp"

#include <cmath>
#include <string>

#include "kinema/error.hpp"

namespace kinema {

std::string term_name(const LocalTerm& term) {
  struct Name {
    const char* operator()(const Gravity&) const { return "gravity"; }
    const char* operator()(const LinearDrag&) const { return "linear_drag"; }
    const char* operator()(const QuadraticDrag&) const { return "quadratic_drag"; }
    const char* operator()(const Spring&) const { return "spring"; }
    const char* operator()(const Central&) const { return "central"; }
    const char* operator()(const Torque&) const { return "torque"; }
    const char* operator()(const AngularDrag&) const { return "angular_drag"; }
    const char* operator()(const PointForce&) const { return "point_force"; }
  };
  return std::visit(Name{}, term);
}

namespace {

void require(bool ok, const LocalTerm& term, const char* field, const char* what) {
  if (!ok) throw Error(term_name(term) + "." + field + ": " + what);
}

bool finite3(const Vec3<double>& v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

bool non_negative(double x) { return std::isfinite(x) && x >= 0; }

void validate(const LocalTerm& term) {
  if (auto* g = std::get_if<Gravity>(&term)) {
    require(finite3(g->g), term, "g", "must be finite");
  } else if (auto* d = std::get_if<LinearDrag>(&term)) {
    require(non_negative(d->k), term, "k", "must be finite and >= 0");
  } else if (auto* q = std::get_if<QuadraticDrag>(&term)) {
    require(non_negative(q->k), term, "k", "must be finite and >= 0");
  } else if (auto* s = std::get_if<Spring>(&term)) {
    require(finite3(s->anchor), term, "anchor", "must be finite");
    require(non_negative(s->k), term, "k", "must be finite and >= 0");
    require(non_negative(s->damping), term, "damping", "must be finite and >= 0");
  } else if (auto* c = std::get_if<Central>(&term)) {
    require(finite3(c->center), term, "center", "must be finite");
    require(non_negative(c->mu), term, "mu", "must be finite and >= 0");
  } else if (auto* t = std::get_if<Torque>(&term)) {
    require(finite3(t->torque), term, "torque", "must be finite");
  } else if (auto* a = std::get_if<AngularDrag>(&term)) {
    require(non_negative(a->c), term, "c", "must be finite and >= 0");
  } else if (auto* p = std::get_if<PointForce>(&term)) {
    require(finite3(p->point), term, "point", "must be finite");
    require(finite3(p->force), term, "force", "must be finite");
  }
}

}  // namespace

template <class T>
ForceModel<T>& ForceModel<T>::add(const LocalTerm& term) {
  validate(term);
  if (std::holds_alternative<Central>(term)) {
    if (central_count_ == kMaxCentralTerms) {
      throw Error("central: at most " + std::to_string(kMaxCentralTerms) +
                  " central terms per model");
    }
    ++central_count_;
  }
  if (std::holds_alternative<PointForce>(term)) {
    if (point_force_count_ == kMaxPointForces) {
      throw Error("point_force: at most " + std::to_string(kMaxPointForces) +
                  " point forces per model");
    }
    ++point_force_count_;
  }
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
ForceModel<T>& ForceModel<T>::add(std::shared_ptr<const CoupledTerm<T>> term) {
  if (!term) throw Error("coupled force: null term");
  coupled_.push_back(std::move(term));
  return *this;
}

template class ForceModel<float>;
template class ForceModel<double>;

}  // namespace kinema
