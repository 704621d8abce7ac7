// Frustum proposal extension of track3d (paper section IV-A).
// Placeholder module proving the C++ build path; the frustum kernels arrive with issue #3.
#include <pybind11/pybind11.h>

namespace py = pybind11;

PYBIND11_MODULE(_frustum, m) {
    m.doc() = "track3d C++ frustum extension";
    m.attr("ABI_VERSION") = 1;
}
