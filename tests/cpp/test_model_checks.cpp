// The models' shared argument checks live in their own header (model_checks.h): it compiles on
// its own, without canopy_model.h, and each check throws std::invalid_argument.
#include "canopy_ao/model_checks.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace canopy_ao {
namespace {

TEST(ModelChecks, HeaderStandsAloneAndRejectsBadShapes) {
  EXPECT_NO_THROW(check_tau(0.0f));
  EXPECT_THROW(check_tau(-1.0f), std::invalid_argument);
  EXPECT_THROW(check_tau(NAN), std::invalid_argument);
  Sphere s;
  s.radius = 1;
  EXPECT_NO_THROW(check_sphere(s));
  s.radius = 0;
  EXPECT_THROW(check_sphere(s), std::invalid_argument);
  Ellipsoid e = Ellipsoid::from_sphere(Sphere{{0, 0, 0}, 1});
  EXPECT_NO_THROW(check_ellipsoid(e));
  e.axes[1] = e.axes[0];
  EXPECT_THROW(check_ellipsoid(e), std::invalid_argument);
  const float p[3] = {0, 0, 0};
  EXPECT_THROW(check_receivers(PointsView{p, 1}, PointsView{p, 0}), std::invalid_argument);
}

}  // namespace
}  // namespace canopy_ao
