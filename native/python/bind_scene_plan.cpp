// Canopy AO — Python binding of the scene plan (scene_plan.h): built once per bake from the
// fitted proxies, evaluated for each item's receivers in one call (GIL released).
// std::invalid_argument from the core becomes ValueError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <string>
#include <vector>

#include "arrays.h"
#include "canopy_ao/scene_plan.h"

namespace canopy_ao::py_bind {

namespace {

PlanMethod plan_method_arg(const std::string& s) {
  if (s == "sphere") return PlanMethod::Sphere;
  if (s == "ellipsoid") return PlanMethod::Ellipsoid;
  if (s == "reeves_blau") return PlanMethod::ReevesBlau;
  if (s == "shells") return PlanMethod::Shells;
  if (s == "medium") return PlanMethod::Medium;
  throw py::value_error("method must be one of \"sphere\", \"ellipsoid\", \"reeves_blau\", "
                        "\"shells\", \"medium\", got \"" + s + "\"");
}

ReceiverRole role_arg(const std::string& s) {
  if (s == "CANOPY") return ReceiverRole::Canopy;
  if (s == "TRUNK") return ReceiverRole::Trunk;
  if (s == "GROUND") return ReceiverRole::Ground;
  if (s == "GRASS") return ReceiverRole::Grass;
  throw py::value_error("role must be \"CANOPY\", \"TRUNK\", \"GROUND\" or \"GRASS\", got \"" +
                        s + "\"");
}

std::vector<TreeProxies> trees_arg(const py::list& crowns, const py::list& trunks) {
  if (crowns.size() != trunks.size()) {
    throw py::value_error("crowns and trunks must have one entry per tree, got " +
                          std::to_string(crowns.size()) + " and " +
                          std::to_string(trunks.size()));
  }
  std::vector<TreeProxies> trees(crowns.size());
  for (std::size_t t = 0; t < trees.size(); ++t) {
    const py::handle c = crowns[t];
    if (!c.is_none()) {
      try {
        if (!py::isinstance<py::sequence>(c) || py::len(c) != 3) throw py::cast_error();
        const auto fit = py::reinterpret_borrow<py::sequence>(c);
        trees[t].sphere = fit[0].cast<Sphere>();
        trees[t].ellipsoid = fit[1].cast<Ellipsoid>();
        trees[t].shells = fit[2].cast<std::vector<Ellipsoid>>();
      } catch (const py::cast_error&) {
        throw py::value_error("crowns[" + std::to_string(t) + "] must be None or (Sphere, "
                              "Ellipsoid, [Ellipsoid]), got " + std::string(py::repr(c)));
      }
      trees[t].has_crown = true;
    }
    try {
      trees[t].trunks = trunks[t].cast<std::vector<Ellipsoid>>();
    } catch (const py::cast_error&) {
      throw py::value_error("trunks[" + std::to_string(t) + "] must be a list of Ellipsoid, got " +
                            std::string(py::repr(trunks[t])));
    }
  }
  return trees;
}

// tau: one number for every tree, or one per tree.
std::vector<float> plan_taus_arg(const py::object& o, std::size_t trees) {
  py::array_t<double, py::array::c_style | py::array::forcecast> a;
  try {
    a = py::array_t<double, py::array::c_style | py::array::forcecast>(o);
  } catch (const py::error_already_set&) {
    throw py::value_error("tau must be a number or one number per tree, got " +
                          std::string(py::repr(o)));
  }
  if (a.ndim() == 0) return std::vector<float>(trees, tau_arg(*a.data()));
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != trees) {
    throw py::value_error("tau must be a number or one number per tree (" +
                          std::to_string(trees) + "), got shape " + shape_str(a));
  }
  std::vector<float> t;
  for (py::ssize_t i = 0; i < a.shape(0); ++i) t.push_back(tau_arg(a.at(i)));
  return t;
}

}  // namespace

void bind_scene_plan(py::module_& m) {
  py::class_<ScenePlan>(
      m, "ScenePlan",
      "Every tree's fitted proxies and solid trunks with their occluder grids, built once per "
      "bake; evaluate() lights receivers of one role in one call: the crown holding a receiver "
      "gives the in-shell model, every other crown and every trunk (not the receiver's own "
      "tree's, for CANOPY and TRUNK) occludes, GRASS gets Hegeman's Eq. 9 (docs/DESIGN.md, "
      "'How each role is lit').")
      .def(py::init([](const py::list& crowns, const py::list& trunks, double distance,
                       float epsilon) {
             std::vector<TreeProxies> trees = trees_arg(crowns, trunks);
             ScenePlanOptions o;
             o.distance = distance_arg(distance);
             o.epsilon = epsilon;
             py::gil_scoped_release release;
             return new ScenePlan(std::move(trees), o);
           }),
           py::arg("crowns"), py::arg("trunks"),
           py::arg("distance") = std::numeric_limits<double>::infinity(),
           py::arg("epsilon") = 1e-3,
           "ScenePlan(crowns, trunks, distance=inf, epsilon=1e-3)\n\n"
           "crowns: per tree, None (no leaves) or (Sphere, Ellipsoid, [Ellipsoid] shells); "
           "trunks: per tree, a list of Ellipsoid (solid; may be empty). A receiver inside "
           "several crowns takes the first one's model. distance: the AO distance (inf = "
           "unlimited); epsilon: the occluders' cut-off (ao_occluders).")
      .def(
          "evaluate",
          [](const ScenePlan& plan, const py::array& positions, const py::array& normals,
             const std::string& role, const py::object& tree, const std::string& method,
             const py::object& tau, const py::object& grass) {
            const Receivers r = receivers_arg(positions, normals);
            PlanReceivers who;
            who.role = role_arg(role);
            const long long n_trees = static_cast<long long>(plan.trees());
            if (py::isinstance<py::array>(tree)) {
              const auto a = py::reinterpret_borrow<py::array>(tree);
              require_dtype(a, "tree", py::dtype::of<std::int32_t>(), "int32");
              if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != r.positions.size) {
                throw py::value_error("tree must be an int or an int32 array of shape (" +
                                      std::to_string(r.positions.size) + ",), got shape " +
                                      shape_str(a));
              }
              who.trees = static_cast<const std::int32_t*>(a.data());
            } else {
              who.tree = static_cast<std::int32_t>(int_arg(tree, "tree", -1, n_trees - 1));
            }
            if ((who.role == ReceiverRole::Grass) == grass.is_none()) {
              throw py::value_error("grass=(ground_height, blade_height) is required for role "
                                    "GRASS and only for it");
            }
            if (!grass.is_none()) {
              std::vector<double> g;
              try {
                g = grass.cast<std::vector<double>>();
              } catch (const py::cast_error&) {
              }
              if (g.size() != 2) {
                throw py::value_error("grass must be (ground_height, blade_height)");
              }
              who.grass.ground_height = coordinate_arg(g[0], "ground_height");
              who.grass.blade_height = length_arg(g[1], "blade_height");
            }
            const PlanMethod pm = plan_method_arg(method);
            const std::vector<float> taus = plan_taus_arg(tau, plan.trees());
            py::array_t<float> out = new_floats(r.positions.size);
            float* o = out.mutable_data();
            {
              py::gil_scoped_release release;
              plan.evaluate(r.positions, r.normals, who, pm, taus, o);
            }
            return out;
          },
          py::arg("positions"), py::arg("normals"), py::arg("role"), py::arg("tree"),
          py::arg("method"), py::arg("tau"), py::arg("grass") = py::none(),
          "evaluate(positions, normals, role, tree, method, tau, grass=None) -> float32 (N,)\n\n"
          "AO in [0, 1] of receivers (float32 (N, 3) each) of one role (\"CANOPY\", "
          "\"TRUNK\", \"GROUND\", \"GRASS\"). tree: the receivers' tree index (-1 = none) or "
          "an int32 (N,) array of them. method: \"sphere\", \"ellipsoid\", \"reeves_blau\", "
          "\"shells\" or \"medium\". tau: one number or one per tree. grass: (ground_height, "
          "blade_height), for role GRASS only.")
      .def_property_readonly("trees", &ScenePlan::trees, "Number of trees.")
      .def(
          "shells",
          [](const ScenePlan& plan, const py::object& tree, const std::string& method) {
            const long long t = int_arg(tree, "tree", 0, static_cast<long long>(plan.trees()) - 1);
            return plan.shells(static_cast<std::size_t>(t), plan_method_arg(method));
          },
          py::arg("tree"), py::arg("method"),
          "The shells `method` lights tree `tree` with (and that occlude for it).")
      .def(
          "max_candidates",
          [](const ScenePlan& plan, const std::string& method) {
            return plan.max_candidates(plan_method_arg(method));
          },
          py::arg("method"), "Largest number of occluders one receiver tests for `method`.");
}

}  // namespace canopy_ao::py_bind
