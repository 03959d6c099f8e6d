// Parameters declared once: a spec row binds a struct member, and one generic loader fills the struct.
//
// The default lives in the struct's default member initializer (so `RoadmapParams p;` and the config
// agree by construction): the factories read it with a constant `P{}.*member`, so P must be a literal
// type. Text members cannot lend a string_view to their default, so a text row names its default and the
// factory refuses to compile when the struct's initializer says otherwise. Every check fails to compile
// naming the rule that was broken (role_table.hpp style); param_field_ok() is the same check at run time.
#pragma once

#include <algorithm>
#include <array>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <variant>

#include "airground/platform/config.hpp"

namespace ag {

// An enum member: the spec's choices ("free|rough|costly") in order, each with its enumerator's value.
template <class P>
struct ParamEnumTarget {
  static constexpr std::size_t kMaxChoices = 8;
  std::int64_t (*get)(const P&) noexcept = nullptr;
  void (*set)(P&, std::int64_t) noexcept = nullptr;
  std::array<std::int64_t, kMaxChoices> values{};
  std::size_t count{0};
};

// One parameter of the struct P: its spec row and the member it fills.
template <class P>
struct ParamField {
  using Target = std::variant<double P::*, float P::*, int P::*, std::int64_t P::*, std::uint8_t P::*, std::uint16_t P::*,
                              std::uint32_t P::*, bool P::*, std::string P::*, ParamEnumTarget<P>>;
  ParamSpec spec;
  Target target;
};

namespace param_check {
// Not constexpr: reached during constant evaluation, the compiler names the rule.
void default_must_lie_within_min_max();
void min_must_not_exceed_max();
void text_default_must_equal_the_struct_initializer();
void enum_default_must_be_one_of_its_choices();
void enum_needs_one_value_per_choice();
void too_many_enum_choices();
}  // namespace param_check

// The i-th '|'-separated choice ("" past the end).
constexpr std::string_view nth_choice(std::string_view choices, std::size_t i) noexcept {
  for (; i > 0; --i) {
    const std::size_t bar = choices.find('|');
    if (bar == std::string_view::npos) return {};
    choices.remove_prefix(bar + 1);
  }
  return choices.substr(0, choices.find('|'));
}

constexpr std::size_t count_choices(std::string_view choices) noexcept {
  return choices.empty() ? 0 : static_cast<std::size_t>(std::count(choices.begin(), choices.end(), '|')) + 1;
}

// True when the row's default lies within [min, max] (numbers); the factories enforce it at compile time.
constexpr bool param_field_ok(const ParamSpec& s) noexcept {
  if (s.type == ParamType::kText || s.type == ParamType::kBool) return true;
  return s.min <= s.max && s.default_num >= s.min && s.default_num <= s.max;
}

// The row named `key`, or nullptr: how a second reader (a mission file) takes a stage's own range.
constexpr const ParamSpec* find_param(std::span<const ParamSpec> rows, std::string_view key) noexcept {
  for (const ParamSpec& r : rows)
    if (r.key == key) return &r;
  return nullptr;
}

namespace detail {
template <class M>
struct member_of;
template <class T, class P>
struct member_of<T P::*> {
  using owner = P;
  using type = T;
};

constexpr ParamSpec checked(const ParamSpec& s) {
  if (s.min > s.max) param_check::min_must_not_exceed_max();
  if (!param_field_ok(s)) param_check::default_must_lie_within_min_max();
  return s;
}

template <auto M>
std::int64_t enum_get(const typename member_of<decltype(M)>::owner& p) noexcept {
  return static_cast<std::int64_t>(p.*M);
}
template <auto M>
void enum_set(typename member_of<decltype(M)>::owner& p, std::int64_t v) noexcept {
  p.*M = static_cast<typename member_of<decltype(M)>::type>(v);
}
}  // namespace detail

// Factories: the default is the member's initializer; ranges, unit and help as in ParamSpec.
namespace field {

template <class P, class T>
  requires std::same_as<T, double> || std::same_as<T, float>
constexpr ParamField<P> real(std::string_view key, T P::*m, double lo, double hi, std::string_view unit,
                             std::string_view help) {
  return {detail::checked(ParamSpec::real(key, static_cast<double>(P{}.*m), lo, hi, unit, help)), m};
}

template <class P, class T>
  requires std::integral<T> && (!std::same_as<T, bool>)
constexpr ParamField<P> integer(std::string_view key, T P::*m, std::int64_t lo, std::int64_t hi, std::string_view unit,
                                std::string_view help) {
  return {detail::checked(ParamSpec::integer(key, static_cast<std::int64_t>(P{}.*m), lo, hi, unit, help)), m};
}

template <class P>
constexpr ParamField<P> boolean(std::string_view key, bool P::*m, std::string_view help) {
  return {ParamSpec::boolean(key, P{}.*m, help), m};
}

// A std::string member; `def` must equal its initializer (checked), `choices` as in ParamSpec::text.
template <class P>
constexpr ParamField<P> text(std::string_view key, std::string P::*m, std::string_view def, std::string_view choices,
                             std::string_view help) {
  if (std::string_view(P{}.*m) != def) param_check::text_default_must_equal_the_struct_initializer();
  return {ParamSpec::text(key, def, choices, help), m};
}

// An enum member M read as text: choice i of `choices` sets values[i]; the default is the initializer's name.
template <auto M, class E = typename detail::member_of<decltype(M)>::type, std::size_t N>
  requires std::is_enum_v<E>
constexpr ParamField<typename detail::member_of<decltype(M)>::owner> choice(std::string_view key, std::string_view choices,
                                                                            const E (&values)[N], std::string_view help) {
  using P = typename detail::member_of<decltype(M)>::owner;
  ParamEnumTarget<P> t{&detail::enum_get<M>, &detail::enum_set<M>, {}, N};
  if (N > t.values.size()) param_check::too_many_enum_choices();
  if (N != count_choices(choices)) param_check::enum_needs_one_value_per_choice();
  std::string_view def{};
  for (std::size_t i = 0; i < N && i < t.values.size(); ++i) {
    t.values[i] = static_cast<std::int64_t>(values[i]);
    if (values[i] == P{}.*M) def = nth_choice(choices, i);
  }
  if (def.empty()) param_check::enum_default_must_be_one_of_its_choices();
  return {ParamSpec::text(key, def, choices, help), t};
}

}  // namespace field

// The plain spec rows of field tables (and of ParamSpec arrays), in order: a stage's kParams.
constexpr const ParamSpec& spec_of(const ParamSpec& s) noexcept { return s; }
template <class P>
constexpr const ParamSpec& spec_of(const ParamField<P>& f) noexcept {
  return f.spec;
}
namespace detail {
template <class R>
struct rows_of;
template <class T, std::size_t N>
struct rows_of<T[N]> {
  static constexpr std::size_t size = N;
};
template <class T, std::size_t N>
struct rows_of<std::array<T, N>> {
  static constexpr std::size_t size = N;
};
}  // namespace detail
template <class... R>
constexpr auto param_specs(const R&... parts) {
  std::array<ParamSpec, (detail::rows_of<R>::size + ...)> out{};
  std::size_t k = 0;
  ((std::for_each(std::begin(parts), std::end(parts), [&](const auto& x) { out[k++] = spec_of(x); })), ...);
  return out;
}

// Fills every member bound in `fields` from section `s`, starting from `out`. Config validated every
// value against these same rows when it was loaded, so loading cannot fail.
template <class P>
void load_params(const SectionView& s, std::span<const ParamField<P>> fields, P& out) {
  for (const ParamField<P>& f : fields) {
    const std::string_view k = f.spec.key;
    std::visit(
        [&](const auto& t) {
          using Target = std::remove_cvref_t<decltype(t)>;
          if constexpr (std::is_same_v<Target, ParamEnumTarget<P>>) {
            const std::string& name = s.text(k);
            for (std::size_t i = 0; i < t.count; ++i)
              if (nth_choice(f.spec.choices, i) == name) t.set(out, t.values[i]);
          } else {
            using T = typename detail::member_of<Target>::type;
            if constexpr (std::is_same_v<T, bool>) out.*t = s.boolean(k);
            else if constexpr (std::is_same_v<T, std::string>) out.*t = s.text(k);
            else if constexpr (std::is_floating_point_v<T>) out.*t = static_cast<T>(s.real(k));
            else out.*t = static_cast<T>(s.integer(k));
          }
        },
        f.target);
  }
}

// The struct at its defaults overlaid with section `s`.
template <class P, std::size_t N>
[[nodiscard]] P load_params(const SectionView& s, const ParamField<P> (&fields)[N]) {
  P p{};
  load_params(s, std::span<const ParamField<P>>(fields), p);
  return p;
}

}  // namespace ag
