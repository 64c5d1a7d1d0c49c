// Small helpers the fitting tests share: packed xyz float vectors as PointsView.
#pragma once

#include <vector>

#include "canopy_ao/geometry.h"

namespace canopy_ao::test {

inline PointsView view(const std::vector<float>& v) { return {v.data(), v.size() / 3}; }

inline void add(std::vector<float>& v, double x, double y, double z) {
  v.push_back(float(x));
  v.push_back(float(y));
  v.push_back(float(z));
}

}  // namespace canopy_ao::test
