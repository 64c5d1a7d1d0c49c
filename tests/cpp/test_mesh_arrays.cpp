// Tests for the mesh arrays of a bake (mesh_arrays.h): world-space receivers, grey colours.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "canopy_ao/mesh_arrays.h"
#include "canopy_ao/parallel.h"

using namespace canopy_ao;

namespace {

std::vector<float> unit_rows(std::size_t n, unsigned seed) {
  std::mt19937 g(seed);
  std::normal_distribution<float> n01;
  std::vector<float> v(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    float x = n01(g), y = n01(g), z = n01(g);
    const float l = std::sqrt(x * x + y * y + z * z);
    v[3 * i] = x / l;
    v[3 * i + 1] = y / l;
    v[3 * i + 2] = z / l;
  }
  return v;
}

}  // namespace

TEST(MeshArrays, IdentityKeepsPositionsAndUnitNormalsBitForBit) {
  const std::size_t n = 100000;  // several parallel blocks
  std::vector<float> p = unit_rows(n, 1), nor = unit_rows(n, 2);
  for (float& x : p) x *= 7.0f;
  const std::vector<float> p0 = p, n0 = nor;
  const double eye[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  to_world_in_place(p.data(), nor.data(), n, eye);
  EXPECT_EQ(std::memcmp(p.data(), p0.data(), p.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(nor.data(), n0.data(), nor.size() * sizeof(float)), 0);
  to_world_in_place(p.data(), nor.data(), n, nullptr);
  EXPECT_EQ(std::memcmp(p.data(), p0.data(), p.size() * sizeof(float)), 0);
}

TEST(MeshArrays, ZeroNaNAndLongNormalsAreFixed) {
  std::vector<float> p(12, 0.0f);
  std::vector<float> nor = {0, 0, 0, NAN, 0, 0, 3, 0, 4, 0, 1e-30f, 0};
  to_world_in_place(p.data(), nor.data(), 4, nullptr);
  const float want[12] = {0, 0, 1, 0, 0, 1, 0.6f, 0, 0.8f, 0, 0, 1};
  for (int i = 0; i < 12; ++i) EXPECT_FLOAT_EQ(nor[i], want[i]) << i;
}

TEST(MeshArrays, AffineTransformAndInverseTransposeNormals) {
  // Non-uniform scale (2, 1, 0.5), a rotation about z by 0.7 and a translation: positions by
  // M p + t, normals by M^-T n renormalised (a tangent plane stays tangent), in double.
  const double c = std::cos(0.7), s = std::sin(0.7);
  const double m[16] = {2 * c, -s, 0, 1.5, 2 * s, c, 0, -2, 0, 0, 0.5, 0.25, 0, 0, 0, 1};
  const std::size_t n = 70000;
  std::vector<float> p = unit_rows(n, 3), nor = unit_rows(n, 4);
  const std::vector<float> p0 = p, n0 = nor;
  to_world_in_place(p.data(), nor.data(), n, m);
  double worst_p = 0, worst_tangent = 0, worst_len = 0;
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double want = m[4 * k] * p0[3 * i] + m[4 * k + 1] * p0[3 * i + 1] +
                          m[4 * k + 2] * p0[3 * i + 2] + m[4 * k + 3];
      worst_p = std::max(worst_p, std::fabs(p[3 * i + k] - want));
    }
    // A tangent t ⟂ n0 maps to M t, which must stay ⟂ the new normal.
    const double t0[3] = {-n0[3 * i + 1], n0[3 * i], 0};
    double mt[3], dot = 0, l2 = 0;
    for (int k = 0; k < 3; ++k) {
      mt[k] = m[4 * k] * t0[0] + m[4 * k + 1] * t0[1] + m[4 * k + 2] * t0[2];
      dot += mt[k] * nor[3 * i + k];
      l2 += double(nor[3 * i + k]) * nor[3 * i + k];
    }
    worst_tangent = std::max(worst_tangent, std::fabs(dot));
    worst_len = std::max(worst_len, std::fabs(l2 - 1));
  }
  EXPECT_LT(worst_p, 1e-5);
  EXPECT_LT(worst_tangent, 1e-5);
  EXPECT_LT(worst_len, 2e-6);
  // A mirror (negative determinant) still gives outward normals: M^-T, not the cofactors.
  const double mirror[16] = {-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  std::vector<float> q = {1, 2, 3}, up = {1, 0, 0};
  to_world_in_place(q.data(), up.data(), 1, mirror);
  EXPECT_FLOAT_EQ(q[0], -1);
  EXPECT_FLOAT_EQ(up[0], -1);
  // A singular matrix (scale 0 on z): the cofactors, which turn a face's normal into that of
  // the face it becomes (along z); one in the plane has no direction left, as a zero normal.
  const double flat[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
  std::vector<float> r = {1, 2, 3, 0, 0, 0}, nz = {0, 0.6f, 0.8f, 0.6f, 0.8f, 0};
  to_world_in_place(r.data(), nz.data(), 2, flat);
  EXPECT_FLOAT_EQ(r[2], 0);
  EXPECT_FLOAT_EQ(nz[1], 0);
  EXPECT_FLOAT_EQ(nz[2], 1);
  EXPECT_FLOAT_EQ(nz[5], 1);
  // Flattened on z, then stood up about x: the quad's normal is its world geometric normal,
  // (1, 0, 0) × (0, 0, 1) = -y, not the object's +z unrotated.
  const double stood[16] = {1, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 1};
  std::vector<float> w = {1, 2, 3}, face = {0, 0, 1};
  to_world_in_place(w.data(), face.data(), 1, stood);
  EXPECT_FLOAT_EQ(face[1], -1);
  EXPECT_NEAR(face[2], 0, 1e-6);
}

TEST(MeshArrays, ThreadCountDoesNotChangeResults) {
  const double m[16] = {0.3, 1.1, 0, 4, -0.2, 0.9, 0.4, 0, 0.1, 0, 2, -1, 0, 0, 0, 1};
  const std::size_t n = 200000;
  std::vector<float> p1 = unit_rows(n, 5), n1 = unit_rows(n, 6);
  std::vector<float> p2 = p1, n2 = n1;
  const int old = set_max_threads(1);
  to_world_in_place(p1.data(), n1.data(), n, m);
  set_max_threads(0);
  to_world_in_place(p2.data(), n2.data(), n, m);
  set_max_threads(old);
  EXPECT_EQ(p1, p2);
  EXPECT_EQ(n1, n2);
}

TEST(MeshArrays, GrayRgba) {
  const std::size_t n = 100001;
  std::vector<float> v(n), rgba(4 * n, -1.0f);
  for (std::size_t i = 0; i < n; ++i) v[i] = float(i % 1000) / 999.0f;
  gray_rgba(v.data(), n, rgba.data());
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(rgba[4 * i], v[i]);
    ASSERT_EQ(rgba[4 * i + 1], v[i]);
    ASSERT_EQ(rgba[4 * i + 2], v[i]);
    ASSERT_EQ(rgba[4 * i + 3], 1.0f);
  }
  gray_rgba(nullptr, 0, nullptr);  // empty: nothing touched
}
