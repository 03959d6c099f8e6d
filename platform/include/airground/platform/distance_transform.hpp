// The exact squared Euclidean distance transform along one line (Felzenszwalb & Huttenlocher, "Distance
// Transforms of Sampled Functions", Theory of Computing 8, 2012): the lower envelope of the parabolas
// (x - q)^2 + f(q) over the source samples q. A 2-D transform is a column pass (each caller's own: the
// distance to the nearest source in its column) followed by this along every row. The localization's
// class distance fields, the mission's regions and the planner's clearance all use it.
//
// Invariants: sources are visited in increasing q; the envelope holds the parabolas that are lowest
// somewhere, v[0..k] with v increasing, and z[i] is where parabola i starts to be the lowest (z[0] = -inf,
// z[k + 1] = +inf). All arithmetic is in Scalar, in the paper's order, so a caller that ran its own copy
// in float or double gets the same bits.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace ag::dt {

// Working memory for lines of up to n samples; size it at start-up, the transform never allocates.
template <typename Scalar>
struct EnvelopeScratch {
  std::vector<std::int32_t> v;  // source sample of each parabola on the envelope
  std::vector<Scalar> f;        // its value f(v)
  std::vector<Scalar> z;        // where it starts to be the lowest
  explicit EnvelopeScratch(std::size_t n = 0) { resize(n); }
  void resize(std::size_t n) {
    v.assign(n + 1, 0);
    f.assign(n + 1, Scalar{0});
    z.assign(n + 2, Scalar{0});
  }
  [[nodiscard]] std::size_t bytes() const noexcept { return v.capacity() * sizeof(std::int32_t) + (f.capacity() + z.capacity()) * sizeof(Scalar); }
};

// Samples q in [0, n) for which source(q) holds are parabolas (x - q)^2 + f(q); emit(x, d2) receives the
// envelope's value at every x in [x0, x1). Returns false, emitting nothing, when no sample is a source.
// Every f(q) is read before the first emit, so emit may overwrite the input. n must not exceed the
// scratch's size.
template <typename Scalar, typename Source, typename Value, typename Emit>
bool squared_distance_line(std::int32_t n, Source&& source, Value&& f, std::int32_t x0, std::int32_t x1, EnvelopeScratch<Scalar>& s,
                           Emit&& emit) noexcept {
  constexpr Scalar kInf = std::numeric_limits<Scalar>::infinity();
  std::int32_t* v = s.v.data();
  Scalar* fv = s.f.data();
  Scalar* z = s.z.data();
  std::int32_t k = -1;
  for (std::int32_t q = 0; q < n; ++q) {
    if (!source(q)) continue;
    const Scalar fq = f(q);
    if (k < 0) {
      k = 0;
      v[0] = q;
      fv[0] = fq;
      z[0] = -kInf;
      z[1] = kInf;
      continue;
    }
    Scalar cut = 0;
    for (;;) {  // z[0] = -inf ends this at k = 0
      const std::int32_t p = v[k];
      cut = ((fq + static_cast<Scalar>(q) * static_cast<Scalar>(q)) - (fv[k] + static_cast<Scalar>(p) * static_cast<Scalar>(p))) /
            (static_cast<Scalar>(2) * static_cast<Scalar>(q - p));
      if (cut > z[k]) break;
      --k;
    }
    ++k;
    v[k] = q;
    fv[k] = fq;
    z[k] = cut;
    z[k + 1] = kInf;
  }
  if (k < 0) return false;
  std::int32_t e = 0;
  for (std::int32_t x = x0; x < x1; ++x) {
    while (z[e + 1] < static_cast<Scalar>(x)) ++e;
    const auto dx = static_cast<Scalar>(x - v[e]);
    emit(x, dx * dx + fv[e]);
  }
  return true;
}

}  // namespace ag::dt
