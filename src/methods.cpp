#include "kinema/methods.hpp"

#include <cmath>
#include <string>

#include "kinema/error.hpp"

namespace kinema {

const Method& method_by_name(std::string_view name) {
  std::string known;
  for (const Method* m : builtin_methods) {
    if (m->name == name) return *m;
    known += (known.empty() ? "" : ", ") + std::string(m->name);
  }
  throw Error("unknown method '" + std::string(name) + "' (known: " + known + ")");
}

namespace {

bool same_coefficients(const Method& a, const Method& b) {
  if (a.kind != b.kind) return false;
  if (a.kind == MethodKind::runge_kutta) {
    return a.tableau.stages == b.tableau.stages && a.tableau.a == b.tableau.a &&
           a.tableau.b == b.tableau.b && a.tableau.c == b.tableau.c;
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
    check(t.stages >= 1 && t.stages <= kMaxStages, m, "stages must be 1..4");
    for (int i = 0; i < kMaxStages; ++i) {
      check(std::isfinite(t.b[i]) && std::isfinite(t.c[i]), m, "non-finite coefficient");
      for (int j = 0; j < kMaxStages; ++j) {
        check(std::isfinite(t.a[i][j]), m, "non-finite coefficient");
        check(j < i || t.a[i][j] == 0, m, "tableau a must be strictly lower triangular");
      }
      check(i < t.stages || (t.b[i] == 0 && t.c[i] == 0), m, "coefficients beyond the last stage");
    }
    return;
  }
  const auto& s = m.scheme;
  check(s.count >= 1 && s.count <= kMaxStages, m, "a scheme has 1..4 operations");
  for (int i = 0; i < s.count; ++i) {
    check(std::isfinite(s.ops[i].weight) && std::isfinite(s.ops[i].time), m,
          "non-finite coefficient");
  }
}

}  // namespace kinema
