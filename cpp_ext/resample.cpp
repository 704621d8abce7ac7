// The trackers' bilinear crop, exposed as track3d._resample.
//
// warp_axis_aligned: an (H, W, 3) uint8 image resampled under an axis-aligned map (a scale and
//   an offset per axis) into an (h, w, 3) uint8 crop, constant or replicated border.
//
// The arithmetic is defined by the numpy reference in runtime/track3d/resample.py (its docstring
// states it); this file follows it operation by operation in float32, with std::fma where the
// reference rounds a * b + c once, and no other contraction (CMakeLists passes
// -ffp-contract=off), so both give the same bytes. The map is separable, so each source row is
// interpolated along x once (the cache of two rows below) and each output row is one pass of
// fma over contiguous floats. target_clones adds an x86-64-v3 variant (AVX2 + FMA: the fma is
// one instruction and the loops vectorise), picked at load time; the default variant calls
// libm's fmaf, which is the same IEEE operation.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <climits>
#include <cstring>
#include <stdexcept>
#include <vector>

namespace py = pybind11;

namespace {

constexpr int64_t kBlock = 16;  // resample.BLOCK: columns in whole blocks take the fma coordinate

using U8Array = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>;
using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

struct Axis {
  std::vector<int64_t> i;  // floor of the source coordinate (clipped to +-2^30 first)
  std::vector<float> f;    // its fraction
};

Axis source(int64_t n, float a, float b, bool blocked) {
  Axis ax;
  ax.i.resize(static_cast<size_t>(n));
  ax.f.resize(static_cast<size_t>(n));
  const int64_t body = blocked ? (n / kBlock) * kBlock : 0;
  for (int64_t x = 0; x < n; ++x) {
    const float xf = static_cast<float>(x);
    float s;
    if (x < body) {
      s = std::fma(a, xf, b);
    } else {
      const float p = xf * a;
      s = p + b;
    }
    // resample._source: clipped at +-2^30, where a float32 has no fraction left (an overflow to
    // inf included), so the cast below is defined
    s = std::min(std::max(s, -1073741824.0f), 1073741824.0f);
    const float fl = std::floor(s);
    ax.i[x] = static_cast<int64_t>(fl);
    ax.f[x] = s - fl;
  }
  return ax;
}

// One source row interpolated along x into (w * 3) floats: t = fma(fx, p1 - p0, p0), where the
// row's pixels (the columns the crop reads, then the border colour) are `px` and
// j0 / j1 are each output column's two neighbours' offsets in it (branch-free: an outside
// neighbour points at the border colour's slot, or at the edge pixel for a replicated border).
__attribute__((target_clones("arch=x86-64-v3", "default")))
void lerp_row(const float* px, const int32_t* j0, const int32_t* j1, const float* fx, int64_t x0, int64_t x1,
              int64_t w, const float* bval, float* out) {
  // columns [0, x0) and [x1, w) have both neighbours outside the image: fma(f, 0, b) = b
  for (int64_t x = 0; x < x0; ++x)
    for (int k = 0; k < 3; ++k) out[x * 3 + k] = bval[k];
  for (int64_t x = x1; x < w; ++x)
    for (int k = 0; k < 3; ++k) out[x * 3 + k] = bval[k];
  for (int64_t x = x0; x < x1; ++x) {
    const float* p0 = px + j0[x];
    const float* p1 = px + j1[x];
    const float f = fx[x];
    out[x * 3 + 0] = std::fma(f, p1[0] - p0[0], p0[0]);
    out[x * 3 + 1] = std::fma(f, p1[1] - p0[1], p0[1]);
    out[x * 3 + 2] = std::fma(f, p1[2] - p0[2], p0[2]);
  }
}

// v = fma(fy, t1 - t0, t0), rounded half to even (the default rounding mode) and clamped.
__attribute__((target_clones("arch=x86-64-v3", "default")))
void blend_rows(const float* t0, const float* t1, float fy, int64_t n, uint8_t* out) {
  for (int64_t j = 0; j < n; ++j) {
    float v = std::nearbyint(std::fma(fy, t1[j] - t0[j], t0[j]));
    v = std::min(std::max(v, 0.0f), 255.0f);
    out[j] = static_cast<uint8_t>(v);
  }
}

py::array_t<uint8_t> warp_axis_aligned(const U8Array& image, const FloatArray& m, int64_t w, int64_t h,
                                       const U8Array& border_value, bool replicate) {
  if (image.ndim() != 3 || image.shape(2) != 3 || image.shape(0) < 1 || image.shape(1) < 1)
    throw std::invalid_argument("image must be (H, W, 3) uint8 with H, W >= 1");
  if (m.size() != 4) throw std::invalid_argument("m must be the four floats [a_x, b_x, a_y, b_y]");
  if (border_value.size() != 3) throw std::invalid_argument("border_value must be three uint8");
  if (w < 1 || h < 1) throw std::invalid_argument("the crop must be at least 1 x 1");
  const int64_t H = image.shape(0), W = image.shape(1);
  const float* mm = m.data();
  const uint8_t* bv = border_value.data();
  const float bval[3] = {static_cast<float>(bv[0]), static_cast<float>(bv[1]), static_cast<float>(bv[2])};
  py::array_t<uint8_t> out({h, w, static_cast<int64_t>(3)});
  uint8_t* o = out.mutable_data();
  const uint8_t* img = image.data();
  {
    py::gil_scoped_release release;
    const Axis cx = source(w, mm[0], mm[1], true);
    const Axis cy = source(h, mm[2], mm[3], false);
    // the source columns the crop reads, [lo, hi], and each output column's neighbours in them
    int64_t lo = W - 1, hi = 0;
    for (int64_t x = 0; x < w; ++x) {
      lo = std::min(lo, std::min(std::max<int64_t>(cx.i[x], 0), W - 1));
      hi = std::max(hi, std::min(std::max<int64_t>(cx.i[x] + 1, 0), W - 1));
    }
    lo = std::min(lo, hi);
    const int64_t n = hi - lo + 1;  // slot n holds the border colour
    std::vector<int32_t> j0(static_cast<size_t>(w)), j1(static_cast<size_t>(w));
    for (int64_t x = 0; x < w; ++x) {
      for (int e = 0; e < 2; ++e) {
        const int64_t c = cx.i[x] + e;
        int64_t slot_of;
        if (replicate) slot_of = std::min(std::max<int64_t>(c, 0), W - 1) - lo;
        else slot_of = (c >= 0 && c < W) ? c - lo : n;
        (e == 0 ? j0 : j1)[x] = static_cast<int32_t>(3 * slot_of);
      }
    }
    // constant border: the output columns with a neighbour inside the image form one run [x0, x1)
    // (the source column grows with the output column)
    int64_t x0 = 0, x1 = w;
    if (!replicate) {
      while (x0 < w && j0[x0] == 3 * n && j1[x0] == 3 * n) ++x0;
      while (x1 > x0 && j0[x1 - 1] == 3 * n && j1[x1 - 1] == 3 * n) --x1;
    }
    // one source row's pixels the crop reads as floats (one vectorised conversion per row: faster
    // than converting at each gather, measured), then the border colour
    std::vector<float> px(static_cast<size_t>(3 * (n + 1)));
    for (int k = 0; k < 3; ++k) px[3 * n + k] = bval[k];
    // two cached source rows: output rows walk the source rows in order (positive scale)
    std::vector<float> buf_a(static_cast<size_t>(w * 3)), buf_b(static_cast<size_t>(w * 3));
    float* slot[2] = {buf_a.data(), buf_b.data()};
    int64_t held[2] = {INT64_MIN, INT64_MIN};
    auto row_of = [&](int64_t r, int64_t protect) -> const float* {
      for (int s = 0; s < 2; ++s)
        if (held[s] == r) return slot[s];
      const int s = held[0] == protect ? 1 : 0;  // never evict the other row this output row needs
      float* out_row = slot[s];
      if (!replicate && (r < 0 || r >= H)) {
        // a row outside the image: every neighbour is the border colour, and fma(f, 0, b) = b
        for (int64_t x = 0; x < w; ++x)
          for (int k = 0; k < 3; ++k) out_row[x * 3 + k] = bval[k];
      } else {
        const uint8_t* row = img + (std::min(std::max<int64_t>(r, 0), H - 1) * W + lo) * 3;
        for (int64_t q = 0; q < 3 * n; ++q) px[q] = static_cast<float>(row[q]);
        lerp_row(px.data(), j0.data(), j1.data(), cx.f.data(), x0, x1, w, bval, out_row);
      }
      held[s] = r;
      return out_row;
    };
    for (int64_t y = 0; y < h; ++y) {
      const int64_t r = cy.i[y];
      const float* t0 = row_of(r, r + 1);
      const float* t1 = row_of(r + 1, r);
      blend_rows(t0, t1, cy.f[y], w * 3, o + y * w * 3);
    }
  }
  return out;
}

}  // namespace

PYBIND11_MODULE(_resample, m) {
  m.doc() = "track3d C++ resampling extension: the trackers' bilinear crop (see track3d.resample)";
  m.attr("ABI_VERSION") = 1;
  m.def("warp_axis_aligned", &warp_axis_aligned, py::arg("image"), py::arg("m"), py::arg("w"), py::arg("h"),
        py::arg("border_value"), py::arg("replicate"),
        "(H,W,3) uint8, float32 [a_x, b_x, a_y, b_y] output->source map, w, h, (3,) uint8 border, "
        "replicate -> (h,w,3) uint8 crop (see track3d.resample)");
}
