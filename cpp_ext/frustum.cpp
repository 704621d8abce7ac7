// Frustum proposal extension of track3d (paper section IV-A), exposed as track3d._frustum.
//
// extract_frustum: one pass over an (N, 3) float32 cloud: depth crop, projection with the
//   3x4 camera matrix, half-open box test; returns the kept points in input order.
// sample_indices / sample_points: the seeded random sampling A3BoxNet needs (SplitMix64).
//
// The semantics are defined by the numpy references in runtime/track3d/frustum.py; the
// arithmetic here follows them operation by operation (float64, same order, no FMA
// contraction: CMakeLists passes -ffp-contract=off) so both select exactly the same points.
// The GIL is released around every loop; no Python object is touched per point.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cmath>
#include <cstdint>
#include <algorithm>
#include <cstring>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace py = pybind11;

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// Selection rule of the paper (IV-A); see frustum_mask_numpy for the reference.
// Branch-free per block: a mask pass the compiler vectorises (no early exits; (x - x) == 0
// is the IEEE test for finite x), then a compaction pass. On real clouds branches would be
// predictable, but a random-looking cloud (noise, NaN holes) costs ~4x with branches.
// target_clones builds an AVX2 variant picked at load time on CPUs that have it; both
// variants compute the same IEEE results (no FMA contraction, no fast-math).
constexpr int64_t kBlock = 1024;

__attribute__((target_clones("avx2", "default")))
void block_mask(const float* pts, int64_t n, const double* b, const double* m, double z_min, double z_max,
                uint8_t* mask) {
  const double x0 = b[0], y0 = b[1];
  const double x1 = b[0] + b[2], y1 = b[1] + b[3];
  for (int64_t i = 0; i < n; ++i) {
    const double x = pts[3 * i], y = pts[3 * i + 1], z = pts[3 * i + 2];
    const double p2 = m[8] * x + m[9] * y + m[10] * z + m[11];
    const double u = (m[0] * x + m[1] * y + m[2] * z + m[3]) / p2;
    const double v = (m[4] * x + m[5] * y + m[6] * z + m[7]) / p2;
    const bool finite = ((x - x) == 0.0) & ((y - y) == 0.0) & ((z - z) == 0.0);
    mask[i] = static_cast<uint8_t>(finite & (z >= z_min) & (z <= z_max) & (p2 > 0.0) & (u >= x0) & (u < x1) &
                                   (v >= y0) & (v < y1));
  }
}

// Mask of the whole cloud (one byte per point), returns the number of kept points.
int64_t frustum_mask(const float* pts, int64_t n, const double* b, const double* m, double z_min, double z_max,
                     uint8_t* mask) {
  if (!(std::isfinite(b[0]) && std::isfinite(b[1]) && std::isfinite(b[2]) && std::isfinite(b[3])) ||
      !(b[2] > 0.0) || !(b[3] > 0.0)) {
    std::memset(mask, 0, static_cast<size_t>(n));
    return 0;
  }
  int64_t k = 0;
  for (int64_t start = 0; start < n; start += kBlock) {
    const int64_t len = std::min(kBlock, n - start);
    block_mask(pts + 3 * start, len, b, m, z_min, z_max, mask + start);
    for (int64_t i = 0; i < len; ++i) k += mask[start + i];
  }
  return k;
}

// The kept points in input order; when `bounds` is given also their per-axis minimum and
// maximum (lo[3], hi[3]; +inf / -inf when none is kept), gathered in the same compaction pass
// so that callers need no second pass over the frustum (kept points are finite by construction).
py::array_t<float> frustum_points(FloatArray points, DoubleArray box2d, DoubleArray M, double z_min,
                                  double z_max, double* bounds) {
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw std::invalid_argument("points must have shape (N, 3)");
  if (box2d.size() != 4) throw std::invalid_argument("box2d must have 4 values [x, y, w, h]");
  if (M.ndim() != 2 || M.shape(0) != 3 || M.shape(1) != 4)
    throw std::invalid_argument("M must have shape (3, 4)");
  const int64_t n = points.shape(0);
  const float* pts = points.data();
  const double* b = box2d.data();
  const double* m = M.data();
  std::vector<uint8_t> mask(static_cast<size_t>(n));
  int64_t k;
  {
    py::gil_scoped_release release;
    k = frustum_mask(pts, n, b, m, z_min, z_max, mask.data());
  }
  py::array_t<float> out({static_cast<py::ssize_t>(k), static_cast<py::ssize_t>(3)});
  float* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    if (bounds == nullptr) {
      for (int64_t i = 0; i < n; ++i) {
        if (mask[static_cast<size_t>(i)]) {
          std::memcpy(o, pts + 3 * i, 3 * sizeof(float));
          o += 3;
        }
      }
    } else {
      float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
      for (int64_t i = 0; i < n; ++i) {
        if (mask[static_cast<size_t>(i)]) {
          const float* p = pts + 3 * i;
          for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], p[a]);
            hi[a] = std::max(hi[a], p[a]);
          }
          std::memcpy(o, p, 3 * sizeof(float));
          o += 3;
        }
      }
      for (int a = 0; a < 3; ++a) {
        bounds[a] = lo[a];
        bounds[3 + a] = hi[a];
      }
    }
  }
  return out;
}

py::array_t<float> extract_frustum(FloatArray points, DoubleArray box2d, DoubleArray M, double z_min,
                                   double z_max) {
  return frustum_points(points, box2d, M, z_min, z_max, nullptr);
}

// (frustum points, (2, 3) float64 [[min x, y, z], [max x, y, z]] of them).
py::tuple extract_frustum_bounds(FloatArray points, DoubleArray box2d, DoubleArray M, double z_min,
                                 double z_max) {
  py::array_t<double> bounds({static_cast<py::ssize_t>(2), static_cast<py::ssize_t>(3)});
  py::array_t<float> pts = frustum_points(points, box2d, M, z_min, z_max, bounds.mutable_data());
  return py::make_tuple(pts, bounds);
}

// SplitMix64 (Steele, Lea, Flood 2014); identical to _SplitMix64 in frustum.py.
struct SplitMix64 {
  uint64_t state;
  explicit SplitMix64(uint64_t seed) : state(seed) {}
  uint64_t next() {
    uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  // Uniform integer in [0, k): 53 random bits times k, keep the top bits (exact, 128-bit).
  uint64_t below(uint64_t k) {
    const unsigned __int128 r = static_cast<unsigned __int128>(next() >> 11) * k;
    return static_cast<uint64_t>(r >> 53);
  }
};

// Without replacement (n >= num): partial Fisher-Yates; with replacement (n < num): every
// index once in order, then num - n random repeats.
void fill_indices(int64_t n, int64_t num, uint64_t seed, int64_t* out) {
  SplitMix64 rng(seed);
  if (n >= num) {
    std::vector<int64_t> idx(static_cast<size_t>(n));
    std::iota(idx.begin(), idx.end(), int64_t{0});
    for (int64_t i = 0; i < num; ++i) {
      const int64_t j = i + static_cast<int64_t>(rng.below(static_cast<uint64_t>(n - i)));
      std::swap(idx[i], idx[j]);
    }
    std::memcpy(out, idx.data(), static_cast<size_t>(num) * sizeof(int64_t));
  } else {
    for (int64_t i = 0; i < n; ++i) out[i] = i;
    for (int64_t i = n; i < num; ++i) out[i] = static_cast<int64_t>(rng.below(static_cast<uint64_t>(n)));
  }
}

void check_sampling(int64_t n, int64_t num) {
  if (num < 1) throw std::invalid_argument("num must be >= 1");
  if (n <= 0) throw std::invalid_argument("cannot sample from an empty point set");
}

py::array_t<int64_t> sample_indices(int64_t n, int64_t num, uint64_t seed) {
  check_sampling(n, num);
  py::array_t<int64_t> out(static_cast<py::ssize_t>(num));
  int64_t* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    fill_indices(n, num, seed, o);
  }
  return out;
}

py::array_t<float> sample_points(FloatArray points, int64_t num, uint64_t seed) {
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw std::invalid_argument("points must have shape (N, 3)");
  const int64_t n = points.shape(0);
  check_sampling(n, num);
  const float* pts = points.data();
  py::array_t<float> out({static_cast<py::ssize_t>(num), static_cast<py::ssize_t>(3)});
  float* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    std::vector<int64_t> idx(static_cast<size_t>(num));
    fill_indices(n, num, seed, idx.data());
    for (int64_t j = 0; j < num; ++j) std::memcpy(o + 3 * j, pts + 3 * idx[j], 3 * sizeof(float));
  }
  return out;
}

// Lone returns (track3d.stray_returns): lone[i] = 1 for each point with no other point in the
// 3 x 3 cells of `cell` pixels around its own, its projection under M in float32 (M's entries
// rounded to float32; u = (row 0 . p) * w, v = (row 1 . p) * w, w = 1 / (row 2 . p), each sum
// left to right); all 0 when fewer than 2 points, a coordinate or projection is not finite, or
// the grid would exceed kMaxCells cells. one_run: the depths of the points that are not lone
// leave no `bucket`-wide slot between their least and greatest empty (buckets from the least
// depth of all), so no two of them in depth order are more than 2 * bucket apart; false whenever
// that was not established. The numpy reference is track3d.frustum.lone_mask_numpy.
constexpr int64_t kMaxCells = int64_t{1} << 24;
constexpr int64_t kMaxBuckets = int64_t{1} << 20;

// The projection with the extents of u, v and z, branch-free so that it vectorises (AVX2 where
// the CPU has it; the same IEEE single-precision results either way: no FMA contraction, no
// fast-math). The extents are kept per lane (8 at a time) and folded at the end: a min / max
// reduction in one variable does not vectorise without fast-math. NaN is passed over by the
// extents; `finite` says whether any coordinate or projection was not finite.
__attribute__((target_clones("avx2", "default")))
void project_extents_f32(const float* pts, int64_t n, const float* m, float* u, float* v, float ext[6],
                         bool* finite) {
  constexpr int kL = 8;
  float lo_u[kL], hi_u[kL], lo_v[kL], hi_v[kL], lo_z[kL], hi_z[kL];
  int ok[kL];
  for (int k = 0; k < kL; ++k) {
    lo_u[k] = lo_v[k] = lo_z[k] = INFINITY;
    hi_u[k] = hi_v[k] = hi_z[k] = -INFINITY;
    ok[k] = 1;
  }
  int64_t i = 0;
  for (; i + kL <= n; i += kL) {
    for (int k = 0; k < kL; ++k) {
      const float x = pts[3 * (i + k)], y = pts[3 * (i + k) + 1], z = pts[3 * (i + k) + 2];
      const float w = 1.0f / (m[8] * x + m[9] * y + m[10] * z + m[11]);
      const float a = (m[0] * x + m[1] * y + m[2] * z + m[3]) * w;
      const float b = (m[4] * x + m[5] * y + m[6] * z + m[7]) * w;
      u[i + k] = a;
      v[i + k] = b;
      ok[k] &= ((a - a) == 0.0f) & ((b - b) == 0.0f) & ((z - z) == 0.0f);
      lo_u[k] = a < lo_u[k] ? a : lo_u[k];
      hi_u[k] = a > hi_u[k] ? a : hi_u[k];
      lo_v[k] = b < lo_v[k] ? b : lo_v[k];
      hi_v[k] = b > hi_v[k] ? b : hi_v[k];
      lo_z[k] = z < lo_z[k] ? z : lo_z[k];
      hi_z[k] = z > hi_z[k] ? z : hi_z[k];
    }
  }
  for (; i < n; ++i) {   // the tail, into lane 0
    const float x = pts[3 * i], y = pts[3 * i + 1], z = pts[3 * i + 2];
    const float w = 1.0f / (m[8] * x + m[9] * y + m[10] * z + m[11]);
    const float a = (m[0] * x + m[1] * y + m[2] * z + m[3]) * w;
    const float b = (m[4] * x + m[5] * y + m[6] * z + m[7]) * w;
    u[i] = a;
    v[i] = b;
    ok[0] &= ((a - a) == 0.0f) & ((b - b) == 0.0f) & ((z - z) == 0.0f);
    lo_u[0] = a < lo_u[0] ? a : lo_u[0];
    hi_u[0] = a > hi_u[0] ? a : hi_u[0];
    lo_v[0] = b < lo_v[0] ? b : lo_v[0];
    hi_v[0] = b > hi_v[0] ? b : hi_v[0];
    lo_z[0] = z < lo_z[0] ? z : lo_z[0];
    hi_z[0] = z > hi_z[0] ? z : hi_z[0];
  }
  bool all_ok = true;
  for (int k = 0; k < 6; k += 2) {
    ext[k] = INFINITY;
    ext[k + 1] = -INFINITY;
  }
  for (int k = 0; k < kL; ++k) {
    all_ok &= ok[k] != 0;
    ext[0] = std::min(ext[0], lo_u[k]);
    ext[1] = std::max(ext[1], hi_u[k]);
    ext[2] = std::min(ext[2], lo_v[k]);
    ext[3] = std::max(ext[3], hi_v[k]);
    ext[4] = std::min(ext[4], lo_z[k]);
    ext[5] = std::max(ext[5], hi_z[k]);
  }
  *finite = all_ok;
}

// Each point's cell (row * nx + column) of `inv`-wide cells from (umin, vmin); vectorises.
__attribute__((target_clones("avx2", "default")))
void cells_f32(const float* u, const float* v, int64_t n, float umin, float vmin, float inv, int32_t nx,
               int32_t* cid) {
  for (int64_t i = 0; i < n; ++i)
    cid[i] = static_cast<int32_t>((v[i] - vmin) * inv) * nx + static_cast<int32_t>((u[i] - umin) * inv);
}

py::tuple lone_scan(FloatArray points, DoubleArray M, double cell, double bucket) {
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw std::invalid_argument("points must have shape (N, 3)");
  if (M.ndim() != 2 || M.shape(0) != 3 || M.shape(1) != 4)
    throw std::invalid_argument("M must have shape (3, 4)");
  if (!(cell > 0.0) || !std::isfinite(cell)) throw std::invalid_argument("cell must be a positive number");
  if (!(bucket > 0.0) || !std::isfinite(bucket)) throw std::invalid_argument("bucket must be a positive number");
  const int64_t n = points.shape(0);
  const float* pts = points.data();
  float m[12];
  for (int k = 0; k < 12; ++k) m[k] = static_cast<float>(M.data()[k]);
  py::array_t<uint8_t> out(static_cast<py::ssize_t>(n));
  uint8_t* o = out.mutable_data();
  bool one_run = false;
  {
    py::gil_scoped_release release;
    std::memset(o, 0, static_cast<size_t>(n));
    if (n >= 2) {
      // buffers kept from call to call (per thread): fresh ones of a large frustum cost page
      // faults every frame, a latency spike of milliseconds now and then
      thread_local std::vector<float> u, v;
      thread_local std::vector<int32_t> cid, count, row;
      thread_local std::vector<uint8_t> occ;
      u.resize(static_cast<size_t>(n));
      v.resize(static_cast<size_t>(n));
      float ext[6];
      bool finite = false;
      project_extents_f32(pts, n, m, u.data(), v.data(), ext, &finite);
      const float umin = ext[0], vmin = ext[2], zmin = ext[4], zmax = ext[5];
      const float inv = 1.0f / static_cast<float>(cell);
      // (u - umin) * inv rises with u (IEEE rounding is monotone), so the largest cell index
      // is the farthest point's: the grid's size and the 1e9 check need no pass of their own
      const float fu_max = (ext[1] - umin) * inv, fv_max = (ext[3] - vmin) * inv;
      if (finite && fu_max < 1e9f && fv_max < 1e9f) {
        const int64_t nx = static_cast<int64_t>(static_cast<int32_t>(fu_max)) + 1;
        const int64_t ny = static_cast<int64_t>(static_cast<int32_t>(fv_max)) + 1;
        if (nx <= kMaxCells / std::max<int64_t>(ny, 1) && nx * ny <= kMaxCells) {
          cid.resize(static_cast<size_t>(n));
          cells_f32(u.data(), v.data(), n, umin, vmin, inv, static_cast<int32_t>(nx), cid.data());
          count.assign(static_cast<size_t>(nx * ny), 0);
          row.assign(static_cast<size_t>(nx * ny), 0);
          for (int64_t i = 0; i < n; ++i) ++count[static_cast<size_t>(cid[i])];
          // the 3 x 3 sums, separably: along each row, then down each column
          for (int64_t r = 0; r < ny; ++r) {
            const int32_t* c = count.data() + r * nx;
            int32_t* w = row.data() + r * nx;
            for (int64_t k = 0; k < nx; ++k) w[k] = c[k] + (k > 0 ? c[k - 1] : 0) + (k + 1 < nx ? c[k + 1] : 0);
          }
          for (int64_t r = 0; r < ny; ++r)
            for (int64_t k = 0; k < nx; ++k)
              count[static_cast<size_t>(r * nx + k)] = row[static_cast<size_t>(r * nx + k)] +
                  (r > 0 ? row[static_cast<size_t>((r - 1) * nx + k)] : 0) +
                  (r + 1 < ny ? row[static_cast<size_t>((r + 1) * nx + k)] : 0);
          for (int64_t i = 0; i < n; ++i) o[i] = static_cast<uint8_t>(count[static_cast<size_t>(cid[i])] == 1);
        }
      }
      // the depth buckets of the points kept
      const double ib = 1.0 / bucket;
      const double span = (static_cast<double>(zmax) - static_cast<double>(zmin)) * ib;
      if (finite && span < static_cast<double>(kMaxBuckets)) {
        const int64_t nb = static_cast<int64_t>(span) + 1;
        occ.assign(static_cast<size_t>(nb), 0);
        const double z0 = static_cast<double>(zmin);
        for (int64_t i = 0; i < n; ++i) {
          const double d = (static_cast<double>(pts[3 * i + 2]) - z0) * ib;
          const int64_t b = std::min(static_cast<int64_t>(d), nb - 1);
          occ[static_cast<size_t>(b)] |= static_cast<uint8_t>(o[i] == 0);
        }
        int64_t lo = 0, hi = nb - 1;
        while (lo < nb && !occ[static_cast<size_t>(lo)]) ++lo;
        while (hi >= 0 && !occ[static_cast<size_t>(hi)]) --hi;
        one_run = hi >= lo;
        for (int64_t b = lo; one_run && b <= hi; ++b) one_run = occ[static_cast<size_t>(b)] != 0;
      }
      // a rare huge call (a cloud spread over a vast grid) does not keep its memory: memory flat
      constexpr size_t kKeep = size_t{1} << 22;
      if (u.capacity() > kKeep) { std::vector<float>().swap(u); std::vector<float>().swap(v); }
      if (cid.capacity() > kKeep) std::vector<int32_t>().swap(cid);
      if (count.capacity() > kKeep) { std::vector<int32_t>().swap(count); std::vector<int32_t>().swap(row); }
      if (occ.capacity() > kKeep) std::vector<uint8_t>().swap(occ);
    }
  }
  return py::make_tuple(out, one_run);
}

}  // namespace

PYBIND11_MODULE(_frustum, m) {
  m.doc() = "track3d C++ frustum extension: frustum proposal (paper IV-A) and point sampling";
  m.attr("ABI_VERSION") = 3;
  m.def("extract_frustum", &extract_frustum, py::arg("points"), py::arg("box2d"), py::arg("M"),
        py::arg("z_min") = 1.0, py::arg("z_max") = 45.0,
        "(N,3) float32 points, [x,y,w,h] box, (3,4) camera matrix -> (n,3) float32 frustum points");
  m.def("extract_frustum_bounds", &extract_frustum_bounds, py::arg("points"), py::arg("box2d"), py::arg("M"),
        py::arg("z_min") = 1.0, py::arg("z_max") = 45.0,
        "as extract_frustum, plus the (2,3) float64 [min; max] of the kept points (+inf/-inf if none)");
  m.def("sample_indices", &sample_indices, py::arg("n"), py::arg("num"), py::arg("seed"),
        "(num,) int64 indices: num of n points, SplitMix64-seeded (see track3d.frustum)");
  m.def("lone_scan", &lone_scan, py::arg("points"), py::arg("M"), py::arg("cell"), py::arg("bucket"),
        "(uint8 (N,): 1 for a point with no other in the 3 x 3 cells of `cell` px around its own, "
        "bool: the others' depths fill every `bucket` between their least and greatest)");
  m.def("sample_points", &sample_points, py::arg("points"), py::arg("num"), py::arg("seed"),
        "(n,3) float32 -> (num,3) float32 sampled points (see track3d.frustum)");
}
