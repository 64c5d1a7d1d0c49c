// Canopy AO — Python binding of the scene plan (scene_plan.h): built once per bake from the
// fitted proxies and the grass covers (grass_cover.h), the instanced forest (forest.h) attached
// to it, evaluated for each item's receivers in one call (GIL released).
// std::invalid_argument from the core becomes ValueError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "arrays.h"
#include "canopy_ao/scene_plan.h"

namespace canopy_ao::py_bind {

namespace {

// A method argument: a PlanMethod (the rungs name its values: core/rungs/*.py) or its name,
// read by the one map from names, which PlanMethod(name) uses too; anything else is a
// ValueError that names the choices.
PlanMethod plan_method_name(const std::string& s) {
  if (s == "sphere") return PlanMethod::Sphere;
  if (s == "ellipsoid") return PlanMethod::Ellipsoid;
  if (s == "reeves_blau") return PlanMethod::ReevesBlau;
  if (s == "shells") return PlanMethod::Shells;
  if (s == "medium") return PlanMethod::Medium;
  throw py::value_error("method must be a PlanMethod or one of \"sphere\", \"ellipsoid\", "
                        "\"reeves_blau\", \"shells\", \"medium\", got \"" + s + "\"");
}

PlanMethod plan_method_arg(const py::object& o) {
  if (py::isinstance<PlanMethod>(o)) return o.cast<PlanMethod>();
  if (py::isinstance<py::str>(o)) return plan_method_name(o.cast<std::string>());
  throw py::value_error("method must be a PlanMethod or its name, got " +
                        std::string(py::repr(o)));
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

// A number checked as coordinate_arg / length_arg do, kept in double (the grass cover's
// arithmetic is double, as the Python formula it replaced).
double coordinate_double(double v, const char* name) {
  coordinate_arg(v, name);
  return v;
}
double length_double(double v, const char* name) {
  length_arg(v, name);
  return v;
}

std::vector<ForestCrowns> forest_crowns_arg(const py::list& crowns) {
  std::vector<ForestCrowns> out(crowns.size());
  for (std::size_t k = 0; k < out.size(); ++k) {
    const py::handle c = crowns[k];
    double tau = 0;
    try {
      if (!py::isinstance<py::sequence>(c) || py::len(c) != 2) throw py::cast_error();
      const auto pair = py::reinterpret_borrow<py::sequence>(c);
      out[k].shells = pair[0].cast<std::vector<Ellipsoid>>();
      tau = pair[1].cast<double>();
    } catch (const py::cast_error&) {
      throw py::value_error("crowns[" + std::to_string(k) + "] must be ([Ellipsoid], tau), got " +
                            std::string(py::repr(c)));
    }
    out[k].tau = tau_arg(tau);
  }
  return out;
}

std::vector<GrassCover> covers_arg(const py::list& covers) {
  std::vector<GrassCover> out;
  for (std::size_t k = 0; k < covers.size(); ++k) {
    try {
      out.push_back(covers[k].cast<GrassCover>());
    } catch (const py::cast_error&) {
      throw py::value_error("grass_covers[" + std::to_string(k) + "] must be a GrassCover, got " +
                            std::string(py::repr(covers[k])));
    }
  }
  return out;
}

void bind_parts(py::module_& m) {
  const char* cover_doc =
      "A grass field as an occluder of the ground under it: the layer's visibility V of an "
      "upward-facing ground point and the field's footprint cells (docs/DESIGN.md, 'How each "
      "role is lit'). A point within one blade height of the ground level sees 1 - f (1 - V), "
      "f the share of the disc of cells of radius max(1, ceil(blade / cell)) around its cell "
      "that the footprint holds; any other point sees 1.";
  py::class_<GrassCover>(m, "GrassCover", cover_doc)
      .def(py::init([](double ground, double blade, double visibility, double cell,
                       const py::object& origin, const py::object& width, const py::array& keys) {
             GrassCoverData d;
             d.ground = coordinate_double(ground, "ground");
             d.blade = length_double(blade, "blade");
             d.visibility = visibility;
             d.cell = length_double(cell, "cell");
             std::vector<double> o;
             try {
               o = origin.cast<std::vector<double>>();
             } catch (const py::cast_error&) {
             }
             if (o.size() != 2) throw py::value_error("origin must be (x, y)");
             d.origin_x = coordinate_double(o[0], "origin x");
             d.origin_y = coordinate_double(o[1], "origin y");
             d.width = int_arg(width, "width", 1, 1LL << 40);
             require_dtype(keys, "keys", py::dtype::of<std::int64_t>(), "int64");
             if (keys.ndim() != 1) {
               throw py::value_error("keys must have shape (K,), got " + shape_str(keys));
             }
             const auto* k = static_cast<const std::int64_t*>(keys.data());
             d.keys.assign(k, k + keys.shape(0));
             return new GrassCover(std::move(d));
           }),
           py::arg("ground"), py::arg("blade"), py::arg("visibility"), py::arg("cell"),
           py::arg("origin"), py::arg("width"), py::arg("keys"),
           "GrassCover(ground, blade, visibility, cell, origin, width, keys)\n\n"
           "ground: the blades' ground level (z); blade: their height; visibility: V in [0, 1]; "
           "cell: the footprint's cell size; origin: (x, y) where cell (0, 0) starts; width: "
           "cells per row; keys: int64 (K,) strictly increasing i * width + j of the cells the "
           "blades stand in.")
      .def(
          "ground_visibility",
          [](const GrassCover& c, const py::array& positions) {
            const PointsView p = points_arg(positions, "positions", /*allow_empty=*/true);
            return compute(p.size, [&](float* o) { c.ground_visibility(p, o); });
          },
          py::arg("positions"),
          "Visibility float32 (N,) under the layer of ground points (float32 (N, 3)).")
      .def_property_readonly(
          "visibility", [](const GrassCover& c) { return c.data().visibility; },
          "V under the layer.");

  py::class_<ForestOccluders, std::shared_ptr<ForestOccluders>>(
      m, "ForestOccluders",
      "A forest's instanced trees as occluders, built once: one occluder field per prototype's "
      "world-space crown shells with its own tau (the medium law), one for every solid trunk; "
      "the visibility is their product (docs/DESIGN.md, 'How each role is lit'). A ScenePlan "
      "it is attached to multiplies it into every receiver.")
      .def(py::init([](const py::list& crowns, const py::list& solids, float epsilon,
                       double distance) {
             std::vector<ForestCrowns> c = forest_crowns_arg(crowns);
             const float d = distance_arg(distance);
             std::vector<Ellipsoid> s;
             try {
               s = solids.cast<std::vector<Ellipsoid>>();
             } catch (const py::cast_error&) {
               throw py::value_error("solids must be a list of Ellipsoid, got " +
                                     std::string(py::repr(solids)));
             }
             py::gil_scoped_release release;
             return new ForestOccluders(std::move(c), std::move(s), epsilon, d);
           }),
           py::arg("crowns"), py::arg("solids"), py::arg("epsilon") = 1e-3,
           py::arg("distance") = std::numeric_limits<double>::infinity(),
           "ForestOccluders(crowns, solids, epsilon=1e-3, distance=inf)\n\n"
           "crowns: per prototype ([Ellipsoid] world-space shells of every instance, tau); "
           "solids: [Ellipsoid] every instance's trunks (opaque); epsilon: the occluders' "
           "cut-off (ao_occluders); distance: the AO distance (inf = unlimited).")
      .def(
          "ao",
          [](const ForestOccluders& f, const py::array& positions, const py::array& normals) {
            const Receivers r = receivers_arg(positions, normals);
            return compute(r.positions.size,
                           [&](float* o) { f.ao(r.positions, r.normals, o); });
          },
          py::arg("positions"), py::arg("normals"),
          "Visibility float32 (N,) in [0, 1] of receivers (float32 (N, 3) each).")
      .def_property_readonly("shells", &ForestOccluders::shells, "Crown shells, all prototypes.")
      .def_property_readonly("solids", &ForestOccluders::solids, "Solid trunks.")
      .def_property_readonly("max_candidates", &ForestOccluders::max_candidates,
                             "Largest number of occluders one receiver tests.");
}

}  // namespace

void bind_scene_plan(py::module_& m) {
  py::enum_<PlanMethod>(m, "PlanMethod",
                        "The rungs the scene plan lights; ScenePlan's methods take one, or its "
                        "name (PlanMethod(name)).")
      .value("sphere", PlanMethod::Sphere)
      .value("ellipsoid", PlanMethod::Ellipsoid)
      .value("reeves_blau", PlanMethod::ReevesBlau)
      .value("shells", PlanMethod::Shells)
      .value("medium", PlanMethod::Medium)
      .def(py::init(&plan_method_name), py::arg("name"));
  bind_parts(m);
  py::class_<ScenePlan>(
      m, "ScenePlan",
      "Every tree's fitted proxies and solid trunks with their occluder grids, built once per "
      "bake; evaluate() lights receivers of one role in one call: the crown holding a receiver "
      "gives the in-shell model, every other crown and every trunk (not the receiver's own "
      "tree's, for CANOPY and TRUNK) occludes, GRASS gets its grass law (ao_grass), GROUND the grass "
      "covers over it, and the attached forest occludes every receiver (docs/DESIGN.md, 'How "
      "each role is lit').")
      .def(py::init([](const py::list& crowns, const py::list& trunks, double distance,
                       float epsilon, const py::list& grass_covers) {
             std::vector<TreeProxies> trees = trees_arg(crowns, trunks);
             std::vector<GrassCover> covers = covers_arg(grass_covers);
             ScenePlanOptions o;
             o.distance = distance_arg(distance);
             o.epsilon = epsilon;
             py::gil_scoped_release release;
             return new ScenePlan(std::move(trees), o, std::move(covers));
           }),
           py::arg("crowns"), py::arg("trunks"),
           py::arg("distance") = std::numeric_limits<double>::infinity(),
           py::arg("epsilon") = 1e-3, py::arg("grass_covers") = py::list(),
           "ScenePlan(crowns, trunks, distance=inf, epsilon=1e-3, grass_covers=[])\n\n"
           "crowns: per tree, None (no leaves) or (Sphere, Ellipsoid, [Ellipsoid] shells); "
           "trunks: per tree, a list of Ellipsoid (solid; may be empty). A receiver inside "
           "several crowns takes the first one's model. distance: the AO distance (inf = "
           "unlimited); epsilon: the occluders' cut-off (ao_occluders); grass_covers: "
           "GrassCover list, the grass fields over the ground (GROUND receivers).")
      .def(
          "evaluate",
          [](const ScenePlan& plan, const py::array& positions, const py::array& normals,
             const std::string& role, const py::object& tree, const py::object& method,
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
              throw py::value_error("grass=(ground_height, blade_height[, layer]) is required "
                                    "for role GRASS and only for it");
            }
            if (!grass.is_none()) {
              std::vector<py::object> g;
              try {
                g = grass.cast<std::vector<py::object>>();
              } catch (const py::cast_error&) {
              }
              if (g.size() != 2 && g.size() != 3) {
                throw py::value_error("grass must be (ground_height, blade_height[, layer])");
              }
              double ground = 0, blade = 0;
              try {
                ground = g[0].cast<double>();
                blade = g[1].cast<double>();
              } catch (const py::cast_error&) {
                throw py::value_error("grass must be (ground_height, blade_height[, layer])");
              }
              who.grass.ground_height = coordinate_arg(ground, "ground_height");
              who.grass.blade_height = length_arg(blade, "blade_height");
              blade_layer_arg(g.size() == 3 ? g[2] : py::none(), &who.grass);
            }
            const PlanMethod pm = plan_method_arg(method);
            const std::vector<float> taus = plan_taus_arg(tau, plan.trees());
            return compute(r.positions.size, [&](float* o) {
              plan.evaluate(r.positions, r.normals, who, pm, taus, o);
            });
          },
          py::arg("positions"), py::arg("normals"), py::arg("role"), py::arg("tree"),
          py::arg("method"), py::arg("tau"), py::arg("grass") = py::none(),
          "evaluate(positions, normals, role, tree, method, tau, grass=None) -> float32 (N,)\n\n"
          "AO in [0, 1] of receivers (float32 (N, 3) each) of one role (\"CANOPY\", "
          "\"TRUNK\", \"GROUND\", \"GRASS\"). tree: the receivers' tree index (-1 = none) or "
          "an int32 (N,) array of them. method: a PlanMethod or its name (\"sphere\", "
          "\"ellipsoid\", \"reeves_blau\", \"shells\" or \"medium\"). tau: one number or one "
          "per tree. grass: (ground_height, "
          "blade_height) or (ground_height, blade_height, layer) with the field's blade layer "
          "(ao_grass), for role GRASS only. GROUND receivers are multiplied by the grass "
          "covers, every receiver by the attached forest.")
      .def_property_readonly("trees", &ScenePlan::trees, "Number of trees.")
      .def_property_readonly("grass_covers", &ScenePlan::grass_covers,
                             "Number of grass covers over the ground.")
      .def(
          "set_forest",
          [](ScenePlan& plan, const py::object& forest) {
            std::shared_ptr<ForestOccluders> f;
            if (!forest.is_none()) {
              try {
                f = forest.cast<std::shared_ptr<ForestOccluders>>();
              } catch (const py::cast_error&) {
                throw py::value_error("forest must be a ForestOccluders or None, got " +
                                      std::string(py::repr(forest)));
              }
            }
            plan.set_forest(std::move(f));
          },
          py::arg("forest"),
          "Attach the instanced forest (ForestOccluders; None: none) every receiver is then "
          "multiplied by, without rebuilding the trees' occluder grids.")
      .def_property_readonly(
          "forest",
          [](const ScenePlan& plan) -> py::object {
            const std::shared_ptr<const ForestOccluders> f = plan.forest();
            if (!f) return py::none();
            return py::cast(std::const_pointer_cast<ForestOccluders>(f));
          },
          "The attached ForestOccluders, or None.")
      .def(
          "shells",
          [](const ScenePlan& plan, const py::object& tree, const py::object& method) {
            const long long t = int_arg(tree, "tree", 0, static_cast<long long>(plan.trees()) - 1);
            return plan.shells(static_cast<std::size_t>(t), plan_method_arg(method));
          },
          py::arg("tree"), py::arg("method"),
          "The shells `method` lights tree `tree` with (and that occlude for it).")
      .def(
          "max_candidates",
          [](const ScenePlan& plan, const py::object& method) {
            return plan.max_candidates(plan_method_arg(method));
          },
          py::arg("method"), "Largest number of occluders one receiver tests for `method`.");
}

}  // namespace canopy_ao::py_bind
