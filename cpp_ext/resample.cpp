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

// One source row r interpolated along x into (w * 3) floats: t = fma(fx, p1 - p0, p0).
__attribute__((target_clones("arch=x86-64-v3", "default")))
void lerp_row(const uint8_t* img, int64_t H, int64_t W, int64_t r, const int64_t* c0, const int64_t* c1,
              const float* fx, int64_t w, const float* bval, bool replicate, float* out) {
  const bool row_in = r >= 0 && r < H;
  const int64_t rr = std::min(std::max<int64_t>(r, 0), H - 1);
  const uint8_t* row = img + rr * W * 3;
  for (int64_t x = 0; x < w; ++x) {
    const int64_t a = c0[x], b = c1[x];
    float p0[3], p1[3];
    if (replicate) {
      const uint8_t* q0 = row + std::min(std::max<int64_t>(a, 0), W - 1) * 3;
      const uint8_t* q1 = row + std::min(std::max<int64_t>(b, 0), W - 1) * 3;
      for (int k = 0; k < 3; ++k) { p0[k] = q0[k]; p1[k] = q1[k]; }
    } else {
      const bool in0 = row_in && a >= 0 && a < W, in1 = row_in && b >= 0 && b < W;
      for (int k = 0; k < 3; ++k) {
        p0[k] = in0 ? static_cast<float>(row[a * 3 + k]) : bval[k];
        p1[k] = in1 ? static_cast<float>(row[b * 3 + k]) : bval[k];
      }
    }
    for (int k = 0; k < 3; ++k) out[x * 3 + k] = std::fma(fx[x], p1[k] - p0[k], p0[k]);
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
    std::vector<int64_t> c1(static_cast<size_t>(w));
    for (int64_t x = 0; x < w; ++x) c1[x] = cx.i[x] + 1;
    // two cached source rows: output rows walk the source rows in order (positive scale)
    std::vector<float> buf_a(static_cast<size_t>(w * 3)), buf_b(static_cast<size_t>(w * 3));
    float* slot[2] = {buf_a.data(), buf_b.data()};
    int64_t held[2] = {INT64_MIN, INT64_MIN};
    auto row_of = [&](int64_t r, int64_t protect) -> const float* {
      for (int s = 0; s < 2; ++s)
        if (held[s] == r) return slot[s];
      const int s = held[0] == protect ? 1 : 0;  // never evict the other row this output row needs
      lerp_row(img, H, W, r, cx.i.data(), c1.data(), cx.f.data(), w, bval, replicate, slot[s]);
      held[s] = r;
      return slot[s];
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
