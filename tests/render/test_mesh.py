"""The vehicle mesh puts every keypoint on its feature (NumPy only, no OpenGL)."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.render.mesh import Appearance, Part, box_mesh, vehicle_geometry, vehicle_mesh
from vfactor.render.dataset import HELD_OUT, TRAIN, random_vehicle
from vfactor.wireframe import PRESETS, Wireframe


def _point_in_triangles(point, triangles, tol=1e-7) -> np.ndarray:
    """Which triangles contain ``point`` (on their plane and inside, barycentric)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=1)
    n_hat = n / area2[:, None]
    on_plane = np.abs(np.einsum("ij,ij->i", point - a, n_hat)) < tol
    w_a = np.einsum("ij,ij->i", np.cross(c - b, point - b), n_hat) / area2
    w_b = np.einsum("ij,ij->i", np.cross(a - c, point - c), n_hat) / area2
    w_c = 1 - w_a - w_b
    return on_plane & (w_a >= -tol) & (w_b >= -tol) & (w_c >= -tol)


def _shapes():
    shapes = [(name, p.wireframe(), p.wheel_radius) for name, p in PRESETS.items()]
    rng = np.random.default_rng(3)
    for split in (TRAIN, HELD_OUT):
        for _ in range(6):
            wf, r, source = random_vehicle(rng, split)
            shapes.append((source, wf, r))
    from vfactor.vehicle_library import library_ids, library_vehicle

    for vehicle_id in library_ids("bus"):  # a windshield at the front of the roof raised "overlap" before
        bus = library_vehicle(vehicle_id)
        shapes.append((vehicle_id, bus.wireframe, bus.wheel_radius))
    return shapes


@pytest.mark.parametrize("name,wireframe,radius", _shapes(), ids=lambda v: v if isinstance(v, str) else "")
def test_keypoints_lie_on_their_features(name, wireframe, radius):
    mesh = vehicle_mesh(wireframe, Appearance(), radius)
    kp = wireframe.vehicle_p_keypoints
    for k in range(4):  # hubs: the centre of the hub cap, in the rim plane
        inside = _point_in_triangles(kp[k], mesh.triangles)
        assert inside.any() and set(mesh.parts[inside]) == {Part.RIM}, (name, k)
    for k in range(4, 8):  # lights: on the light's outer corner edge (front/back face and side)
        part = Part.HEAD_LIGHT if k < 6 else Part.TAIL_LIGHT
        inside = _point_in_triangles(kp[k], mesh.triangles)
        assert inside.any() and set(mesh.parts[inside]) == {part}, (name, k, set(mesh.parts[inside]))
    for k in range(8, 12):  # roof: a corner shared by glass and paint
        d = np.linalg.norm(mesh.triangles - kp[k], axis=2).min(axis=1)
        parts = set(mesh.parts[d < 1e-9])
        assert Part.GLASS in parts and Part.BODY in parts, (name, k, parts)


def test_wheels_stand_on_the_road_and_nothing_goes_below():
    p = PRESETS["bmw_x5"]
    mesh = vehicle_mesh(p.wireframe(), None, p.wheel_radius)
    z = mesh.vertices[:, 2]
    tyre = mesh.vertices[np.repeat(mesh.parts == Part.TYRE, 3), 2]
    assert z.min() >= -p.wheel_radius - 1e-9
    assert tyre.min() < -p.wheel_radius * np.cos(np.radians(10.0)) + 1e-9  # an 18-gon's lowest vertices


def test_asymmetric_wireframe_is_warped_onto_its_keypoints():
    p = PRESETS["hatchback"]
    points = np.array(p.wireframe().vehicle_p_keypoints)
    points[4] += [0.02, -0.03, 0.02]  # left front light moved
    points[10] += [0.03, 0.0, -0.02]  # left rear-window corner moved
    wf = Wireframe(points)
    mesh = vehicle_mesh(wf, None, p.wheel_radius)
    for k in (4, 10):  # keypoints are mesh vertices, which the thin-plate warp maps exactly
        assert np.linalg.norm(mesh.triangles - points[k], axis=2).min() < 1e-9, k
    assert _point_in_triangles(points[4], mesh.triangles, tol=1e-9).any()


@pytest.mark.parametrize("model", ["citroen_jumper_l3h3", "toyota_camry_xv70_se", "ford_transit_connect_2014_l1"])
def test_a_roof_at_the_published_height_stands_on_the_window_tops(model):
    from vfactor.vehicle_library import vehicle_library

    vehicle = vehicle_library()[model]
    wf, radius = vehicle.wireframe, 0.34
    roof = vehicle.dimensions.height - radius
    low, high = vehicle_mesh(wf, None, radius), vehicle_mesh(wf, None, radius, roof=roof)
    kp = wf.vehicle_p_keypoints
    assert low.vertices[:, 2].max() == pytest.approx(kp[8:, 2].max())  # without: the roof is at the window tops
    assert high.vertices[:, 2].max() == pytest.approx(roof) and roof > kp[8:, 2].max() + 0.05
    assert high.vertices[:, 2].min() == pytest.approx(low.vertices[:, 2].min())
    for k in range(8, 12):  # the window tops are still vertices of the glass and the paint
        d = np.linalg.norm(high.triangles - kp[k], axis=2).min(axis=1)
        assert {Part.GLASS, Part.BODY} <= set(high.parts[d < 1e-9]), (model, k)
    top = high.triangles[np.all(np.isclose(high.triangles[..., 2], roof), axis=1)]
    assert len(top) == 2  # the roof: one quad over the four window tops
    np.testing.assert_allclose(np.sort(top.reshape(-1, 3)[:, :2], axis=0)[[0, -1]],
                               np.sort(kp[8:, :2], axis=0)[[0, -1]])
    # a roof at (or under) the window tops adds nothing
    same = vehicle_mesh(wf, None, radius, roof=float(kp[8:, 2].max()))
    np.testing.assert_array_equal(same.triangles, low.triangles)


def test_geometry_rejects_reversed_wireframes():
    wf = PRESETS["lincoln_mkz"].wireframe()
    with pytest.raises(ValueError, match="along body x"):
        vehicle_geometry(Wireframe(wf.vehicle_p_keypoints * [-1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="wheel_radius"):
        vehicle_mesh(wf, None, wheel_radius=0.0)


def test_mesh_transform_and_props():
    box = box_mesh([1.0, 2.0, 0.5], (2.0, 1.0, 1.0), yaw=0.0)
    assert len(box) == 12
    assert np.allclose(box.vertices.min(0), [0.0, 1.5, 0.0]) and np.allclose(box.vertices.max(0), [2.0, 2.5, 1.0])
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.0, 3.0]
    assert np.allclose(box.transformed(T).vertices[:, 2].min(), 3.0)
