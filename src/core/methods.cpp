#include "kinema/methods.hpp"

#include <array>
#include <cmath>
#include <span>
#include <string>

#include "kinema/error.hpp"

namespace kinema {

const Method& method_by_name(std::string_view name) {
  std::string known;
  for (const auto& list : {std::span<const Method* const>(builtin_methods), std::span<const Method* const>(staged_methods),
                           std::span<const Method* const>(implicit_methods)}) {
    for (const Method* m : list) {
      if (m->name == name) return *m;
      known += (known.empty() ? "" : ", ") + std::string(m->name);
    }
  }
  throw Error("unknown method '" + std::string(name) + "' (known: " + known + ")");
}

namespace {

bool same_coefficients(const Method& a, const Method& b) {
  if (a.kind != b.kind) return false;
  if (a.kind == MethodKind::runge_kutta) {
    return a.tableau.stages == b.tableau.stages && a.tableau.a == b.tableau.a &&
           a.tableau.b == b.tableau.b && a.tableau.c == b.tableau.c && a.tableau.b_hat == b.tableau.b_hat;
  }
  if (a.kind == MethodKind::linearly_implicit) {
    const auto &x = a.rosenbrock, &y = b.rosenbrock;
    return x.stages == y.stages && x.gamma == y.gamma && x.a == y.a && x.c == y.c && x.m == y.m && x.time == y.time;
  }
  if (a.scheme.count != b.scheme.count) return false;
  for (int i = 0; i < a.scheme.count; ++i) {
    const auto &x = a.scheme.ops[i], &y = b.scheme.ops[i];
    if (x.kind != y.kind || x.weight != y.weight || x.time != y.time) return false;
  }
  return true;
}

void check(bool ok, const Method& m, const std::string& what) {
  if (!ok) throw Error("method '" + std::string(m.name) + "': " + what);
}

void validate_rosenbrock(const Method& m) {
  const RosenbrockScheme& r = m.rosenbrock;
  check(r.stages >= 1 && r.stages <= kMaxRosenbrockStages, m,
        "a Rosenbrock scheme has 1.." + std::to_string(kMaxRosenbrockStages) + " stages");
  check(std::isfinite(r.gamma) && r.gamma > 0, m, "gamma must be finite and > 0");
  check(m.embedded_order == 0, m, "a Rosenbrock scheme here has no embedded pair");
  for (int i = 0; i < kMaxRosenbrockStages; ++i) {
    check(std::isfinite(r.m[i]) && std::isfinite(r.time[i]), m, "non-finite coefficient");
    check(i < r.stages || (r.m[i] == 0 && r.time[i] == 0), m, "coefficients beyond the last stage");
    for (int j = 0; j < kMaxRosenbrockStages; ++j) {
      check(std::isfinite(r.a[i][j]) && std::isfinite(r.c[i][j]), m, "non-finite coefficient");
      check(j < i || (r.a[i][j] == 0 && r.c[i][j] == 0), m, "a and c must be strictly lower triangular");
    }
  }
}

}  // namespace

int builtin_index(const Method& method) {
  for (std::size_t i = 0; i < builtin_methods.size(); ++i) {
    if (same_coefficients(method, *builtin_methods[i])) return int(i);
  }
  return -1;
}

void validate(const Method& m) {
  if (m.kind == MethodKind::runge_kutta) {
    const auto& t = m.tableau;
    check(t.stages >= 1 && t.stages <= kMaxStages, m, "stages must be 1.." + std::to_string(kMaxStages));
    bool any_b_hat = false;
    for (int i = 0; i < kMaxStages; ++i) {
      check(std::isfinite(t.b[i]) && std::isfinite(t.c[i]) && std::isfinite(t.b_hat[i]), m,
            "non-finite coefficient");
      any_b_hat |= t.b_hat[i] != 0;
      check(i < t.stages || t.b_hat[i] == 0, m, "coefficients beyond the last stage");
      for (int j = 0; j < kMaxStages; ++j) {
        check(std::isfinite(t.a[i][j]), m, "non-finite coefficient");
        check(j < i || t.a[i][j] == 0, m, "tableau a must be strictly lower triangular");
      }
      check(i < t.stages || (t.b[i] == 0 && t.c[i] == 0), m, "coefficients beyond the last stage");
    }
    check(any_b_hat == (m.embedded_order > 0), m, "embedded weights b_hat and embedded_order go together");
    check(m.embedded_order >= 0 && m.embedded_order < m.order + 1, m, "embedded_order out of range");
    return;
  }
  if (m.kind == MethodKind::linearly_implicit) return validate_rosenbrock(m);
  const auto& s = m.scheme;
  check(s.count >= 1 && s.count <= kMaxStages, m, "a scheme has 1.." + std::to_string(kMaxStages) + " operations");
  check(m.embedded_order == 0, m, "a kick-drift scheme has no embedded pair");
  for (int i = 0; i < s.count; ++i) {
    check(std::isfinite(s.ops[i].weight) && std::isfinite(s.ops[i].time), m,
          "non-finite coefficient");
  }
}

}  // namespace kinema
