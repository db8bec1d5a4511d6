#include "kinema/forces.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "force_terms.hpp"
#include "kinema/error.hpp"

namespace kinema {

std::string term_name(const LocalTerm& term) {
  return visit_term(term, [](const auto&, auto info) { return std::string(info.name); });
}

namespace {

// Every parameter in its range: vectors finite, numbers finite and >= 0.
template <class Term, class Info>
void validate(const Term& t, Info info) {
  for_each_field(info, [&](const auto& field) {
    const auto& value = t.*field.member;
    if constexpr (std::decay_t<decltype(field)>::is_vector) {
      if (!(std::isfinite(value[0]) && std::isfinite(value[1]) && std::isfinite(value[2]))) {
        throw Error(std::string(info.name) + "." + field.key + ": must be finite");
      }
    } else if (!(std::isfinite(value) && value >= 0)) {
      throw Error(std::string(info.name) + "." + field.key + ": must be finite and >= 0");
    }
  });
}

}  // namespace

template <class T>
ForceModel<T>& ForceModel<T>::add(const LocalTerm& term) {
  visit_term(term, [&](const auto& t, auto info) {
    validate(t, info);
    if constexpr (decltype(info)::max_count > 0) {
      const auto same = [&](const LocalTerm& other) { return other.index() == term.index(); };
      if (std::count_if(local_.begin(), local_.end(), same) == info.max_count) {
        throw Error(std::string(info.name) + ": at most " + std::to_string(info.max_count) +
                    " per model");
      }
    }
  });
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
