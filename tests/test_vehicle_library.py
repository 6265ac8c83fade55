"""The vehicle library: published dimensions, keypoints derived from them, HWC admits every vehicle."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from vfactor.factors.rectangle import rectangle_factor
from vfactor.factors.symmetry import symmetry_factor
from vfactor.graph import GraphConfig, hwc_terms, hwc_violation, insert_vehicle_values
from vfactor.keys import KeyScheme
from vfactor.shape_model import default_hwc_bounds, default_shape_model
from vfactor.sim.vehicles import within_hwc_bounds
from vfactor.vehicle_library import (
    BODY_RULES,
    BODY_TYPES,
    BodyRules,
    VehicleDimensions,
    bounds_vehicles,
    keypoints_from_dimensions,
    library_ids,
    library_vehicle,
    tyre_radius,
    vehicle_library,
)


def test_library_covers_every_body_type():
    library = vehicle_library()
    assert len(library) >= 40
    for body_type in BODY_TYPES:
        assert len(library_ids(body_type)) >= 5, body_type
    vans = [v.dimensions for v in library.values() if v.body_type == "van"]
    assert sum(v.roof == "high" for v in vans) >= 3  # high-roof panel vans
    assert sum(v.height < 1.95 for v in vans) >= 3  # two-box (compact) vans
    for v in library.values():
        assert v.dimensions.source and v.dimensions.make and v.dimensions.model, v.id


def test_every_library_vehicle_satisfies_every_hwc_condition():
    """The nonlinear terms and the linear wheel-layer and symmetry factors: zero residual for every vehicle."""
    terms = hwc_terms(GraphConfig(), default_hwc_bounds())
    keys = KeyScheme().layer_keys(0)
    linear = [rectangle_factor(keys[0]), *(symmetry_factor(k) for k in keys)]
    for v in [*vehicle_library().values(), *bounds_vehicles().values()]:
        assert hwc_violation(v.wireframe, terms) == 0.0, v.id
        assert within_hwc_bounds(v.wireframe), v.id
        values = gtsam.Values()
        insert_vehicle_values(values, KeyScheme(), None, v.wireframe)
        assert max(f.error(values) for f in linear) < 1e-20, v.id


def test_hwc_bounds_learnt_without_a_vehicle_still_admit_it():
    """Leave-one-model-out: the bounds are physical, not a span of the sample."""
    for vehicle_id in library_ids():
        bounds = default_shape_model(frozenset({vehicle_id})).bounds
        assert hwc_violation(library_vehicle(vehicle_id).wireframe, hwc_terms(GraphConfig(), bounds)) == 0.0, vehicle_id


def test_tyre_radius_from_the_iso_size():
    assert tyre_radius("205/55R16") == pytest.approx((16 * 25.4 / 2 + 205 * 0.55) / 1000)
    assert tyre_radius("LT275/65R18") == pytest.approx((18 * 25.4 / 2 + 275 * 0.65) / 1000)
    assert tyre_radius("215/65R16C") == pytest.approx((16 * 25.4 / 2 + 215 * 0.65) / 1000)
    with pytest.raises(ValueError, match="tyre"):
        tyre_radius("wide and round")


def test_keypoints_follow_the_dimensions():
    for v in vehicle_library().values():
        d, p = v.dimensions, v.wireframe.vehicle_p_keypoints
        r = d.wheel_radius
        front, rear = d.overhangs()
        assert front + rear + d.wheelbase == pytest.approx(d.length)
        np.testing.assert_allclose(p[:4, 0], [d.wheelbase / 2] * 2 + [-d.wheelbase / 2] * 2)
        np.testing.assert_allclose(np.abs(p[:4, 1]), [d.front_track / 2] * 2 + [d.rear_track / 2] * 2)
        np.testing.assert_allclose(p[:4, 2], 0.0)
        np.testing.assert_allclose(p[:4].mean(axis=0), 0.0, atol=1e-12)  # the body origin
        assert np.all(p[:, 0] <= d.wheelbase / 2 + front) and np.all(p[:, 0] >= -(d.wheelbase / 2 + rear)), v.id
        assert np.all(np.abs(p[:, 1]) <= d.width / 2), v.id
        assert np.all(p[:, 2] + r <= d.height) and np.all(p[:, 2] + r > 0), v.id
        assert p[4, 0] > d.wheelbase / 2 and p[6, 0] < -d.wheelbase / 2, v.id  # lamps beyond the axles
        assert p[8, 0] > p[10, 0], v.id  # windshield ahead of the rear window
        np.testing.assert_allclose(p[[1, 3, 5, 7, 9, 11]], p[[0, 2, 4, 6, 8, 10]] * [1, -1, 1])  # mirror images


def test_rear_window_follows_the_body_type():
    library = vehicle_library()
    pickup = next(v for v in library.values() if v.body_type == "pickup")
    d = pickup.dimensions
    rear_end = -(d.wheelbase / 2 + d.overhangs()[1])
    cab_back = pickup.wireframe.vehicle_p_keypoints[10, 0]
    assert cab_back == pytest.approx(rear_end + d.bed_length + BODY_RULES["pickup"].rear_window_offset)
    sedan = next(v for v in library.values() if v.body_type == "sedan")
    assert sedan.wireframe.vehicle_p_keypoints[10, 0] > -sedan.dimensions.wheelbase / 2  # ahead of the rear axle


def test_dimensions_without_overhangs_split_by_body_type():
    d = VehicleDimensions("x", "M", "X", "", "", "suv", 4.6, 1.85, 1.7, 2.7, 1.6, 1.6, "225/65R17")
    front, rear = d.overhangs()
    assert front == pytest.approx(BODY_RULES["suv"].front_overhang_share * 1.9) and front + rear == pytest.approx(1.9)
    assert keypoints_from_dimensions(d).wheelbase == pytest.approx(2.7)


def test_unknown_ids_and_types_are_refused():
    with pytest.raises(ValueError, match="unknown id"):
        library_vehicle("tractor")
    with pytest.raises(ValueError, match="body type"):
        library_ids("tractor")


def test_docs_list_every_vehicle_as_the_library_has_it():
    from pathlib import Path

    from vfactor.vehicle_library import library_table

    page = (Path(__file__).resolve().parents[1] / "docs" / "vehicles.md").read_text(encoding="utf-8")
    assert library_table() in page


def test_the_bounds_span_the_buses_and_the_roads_extremes_beyond_the_library():
    """The library's buses, a microcar and the largest two-axle bus EU rules allow are vehicles to HWC; the priors
    and the simulator never see the extremes, and the simulator's random cars keep the bounds of the cars and the
    light vehicles (so that seeds keep their scenes), which admit no bus."""
    extremes = bounds_vehicles()
    lengths = sorted(v.dimensions.length for v in extremes.values())
    assert lengths[0] < 2.8 and lengths[-1] >= 13.5
    assert not set(extremes) & set(vehicle_library())
    assert not set(extremes) & {v for t in default_shape_model().types for v in library_ids(t)}
    light = default_hwc_bounds(road_extremes=False)
    assert not within_hwc_bounds(extremes["eu_maximum_two_axle_bus"].wireframe, light)
    buses = [library_vehicle(v).wireframe for v in library_ids("bus")]
    assert len(buses) >= 5 and not any(within_hwc_bounds(w, light) for w in buses)
    assert all(within_hwc_bounds(w, default_hwc_bounds()) for w in [*buses, *(v.wireframe for v in extremes.values())])
    for v in extremes.values():
        assert v.dimensions.source, v.id


def test_a_vehicle_of_a_body_type_of_ones_own_needs_rules_and_gets_a_clear_error_without():
    """keypoints_from_dimensions with rules for a body type vfactor has none for raised KeyError (the overhang
    split looked the rules up by body type; a bus was the example until the library had buses)."""
    dims = VehicleDimensions(id="my_truck", make="x", model="y", generation="", variant="", body_type="truck",
                             length=12.0, width=2.55, height=3.2, wheelbase=6.0, front_track=2.1, rear_track=1.85,
                             tyre="275/70R22.5")
    rules = BodyRules(0.45, 0.05, 0.75, 0.2, 0.03, 1.1, 0.12, 0.0, -2.6, 10.0, 0.15, 0.1, "end", 0.05, 0.4)
    wireframe = keypoints_from_dimensions(dims, rules)
    assert wireframe.vehicle_p_keypoints[0, 0] == pytest.approx(3.0)  # front hubs at half the wheelbase
    assert dims.overhangs(rules) == pytest.approx((0.45 * 6.0, 0.55 * 6.0))
    with pytest.raises(ValueError, match="no BodyRules for body type 'truck'"):
        keypoints_from_dimensions(dims)


def test_layer_offset_bounds_are_one_row_per_axis():
    """[[x_min, x_max], [z_min, z_max]] as every reader takes them: they were stored transposed, which made the x
    range [x_min, z_min] and the z range [x_max, z_max]."""
    from vfactor.keypoints import LAYERS
    from vfactor.shape_model import HwcBounds

    shapes = [v.wireframe for v in vehicle_library().values()]
    bounds = HwcBounds.from_wireframes(shapes, margin=0.0)
    pts = np.array([w.vehicle_p_keypoints for w in shapes])
    for name in ("light", "roof"):
        off = pts[:, list(LAYERS[name])].mean(1) - pts[:, list(LAYERS["wheel"])].mean(1)
        box = bounds.layer_offset[name]
        np.testing.assert_allclose(box[0], [off[:, 0].min() - 0.1, off[:, 0].max() + 0.1])  # x (the 10 cm minimum)
        np.testing.assert_allclose(box[1], [off[:, 2].min() - 0.1, off[:, 2].max() + 0.1])  # z


def test_a_buses_windshield_top_is_at_the_front_of_its_roof_whatever_its_front_overhang():
    """BodyRules.windshield_setback: the windshield top sits that far behind the front end (a bus's front overhangs
    differ by 0.6 m across the library), not at a share of the wheelbase behind the front axle as a car's."""
    from vfactor.vehicle_library import BODY_RULES

    rules = BODY_RULES["bus"]
    for vehicle_id in library_ids("bus"):
        vehicle = library_vehicle(vehicle_id)
        front, _ = vehicle.dimensions.overhangs()
        x_front = vehicle.dimensions.wheelbase / 2 + front
        points = vehicle.wireframe.vehicle_p_keypoints
        np.testing.assert_allclose(points[8:10, 0], x_front - rules.windshield_setback, atol=1e-12)
        assert points[8, 0] > points[4, 0] - 0.2  # near the front lamps, unlike a car's windshield
