"""Training samples: deterministic, consistent keypoints/ROI/flags, held-out split, npz round trip."""

from __future__ import annotations

import numpy as np
import pytest

from vfactor.heatmaps import image_to_heatmap
from vfactor.render.dataset import (
    HELD_OUT,
    TRAIN,
    crop_camera,
    load_dataset,
    make_dataset,
    random_training_sample,
    roi_from_box,
    sample_rng,
)
from vfactor.vehicle_library import BODY_TYPES, LIGHT_TYPES, library_ids, library_vehicle


@pytest.fixture(scope="module")
def samples(gl_context):
    return [random_training_sample(sample_rng(5, i), 96) for i in range(6)]


def test_samples_are_deterministic(gl_context):
    a = random_training_sample(np.random.default_rng(11), 64)
    b = random_training_sample(np.random.default_rng(11), 64)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.keypoints, b.keypoints)
    assert np.array_equal(a.roi, b.roi) and a.meta == b.meta
    c = random_training_sample(np.random.default_rng(12), 64)
    assert not np.array_equal(a.image, c.image)


def test_keypoints_roi_and_flags_are_consistent(samples):
    for s in samples:
        assert s.image.shape == (96, 96, 3) and s.image.dtype == np.uint8
        assert s.keypoints.shape == (12, 2) and np.all(np.isfinite(s.keypoints))
        # Crop pixels are the full-image pixels mapped through the ROI (vfactor.heatmaps' convention).
        full = s.keypoints_full
        assert np.allclose(image_to_heatmap(full, s.roi, (96, 96)), s.keypoints, atol=1e-6)
        assert np.allclose(s.crop.project(s.wireframe.in_world(s.world_T_vehicle))[0], s.keypoints, atol=1e-6)
        # The ROI holds the whole vehicle box with the margin, so every keypoint is in the crop.
        box = np.array(s.meta["box"])
        assert s.roi[0] <= box[0] and s.roi[1] <= box[1] and s.roi[2] >= box[2] and s.roi[3] >= box[3]
        assert s.in_crop.all()
        side = s.roi[2] - s.roi[0]
        assert np.isclose(side, s.roi[3] - s.roi[1])  # square by default
        assert 1.2 - 1e-9 <= side / max(box[2] - box[0], box[3] - box[1]) <= 1.6 + 1e-9
        assert not (s.visible & (s.self_occluded | s.occluded_by_other)).any()
        assert (s.visible | s.self_occluded | s.occluded_by_other | ~s.camera.in_image(full)).all()
        assert s.self_occluded.sum() >= 2  # a car always hides some of its own keypoints
        assert s.meta["split"] == "train"


def test_held_out_split_draws_other_shapes_colours_and_views(gl_context):
    for i in range(4):
        s = random_training_sample(sample_rng(5, i, held_out=True), 64, held_out=True)
        m = s.meta
        assert m["split"] == "held_out"
        source = m["source"]
        assert (source in HELD_OUT.presets or source in HELD_OUT.library_models
                or int(source.split(":")[1]) in HELD_OUT.pascal_models)
        assert HELD_OUT.azimuth_ok(m["azimuth_deg"]) and not TRAIN.azimuth_ok(m["azimuth_deg"])
        assert HELD_OUT.elevation_ok(m["elevation_deg"]) and not TRAIN.elevation_ok(m["elevation_deg"])
    assert not set(HELD_OUT.presets) & set(TRAIN.presets)
    assert not set(HELD_OUT.pascal_models) & set(TRAIN.pascal_models)
    assert not set(HELD_OUT.library_models) & set(TRAIN.library_models)
    assert set(HELD_OUT.library_models) | set(TRAIN.library_models) == {v for t in LIGHT_TYPES for v in library_ids(t)}
    for split in (TRAIN, HELD_OUT):  # every light body type in both halves of the library (no bus: see library_split)
        assert {library_vehicle(v).body_type for v in split.library_models} == set(LIGHT_TYPES)
    assert TRAIN.hue_ok(5.0) and HELD_OUT.hue_ok(25.0) and not TRAIN.hue_ok(25.0)


def test_roi_and_crop_camera_conventions():
    roi = roi_from_box([100, 50, 180, 90], margin=0.25, square=True, jitter=(0.1, 0.0))
    assert np.allclose(roi[2] - roi[0], 80 * 1.5) and np.allclose(roi[3] - roi[1], 80 * 1.5)
    assert np.isclose(0.5 * (roi[0] + roi[2]), 140 + 0.1 * 120)
    from vfactor.sim.rig import pole_camera

    cam = pole_camera("c", (10, 5), 7.0)
    crop = crop_camera(cam, roi, 64)
    pts = np.array([[0.5, 0.2, 0.7], [-1.0, 0.3, 0.2]])
    assert np.allclose(crop.project(pts)[0], image_to_heatmap(cam.project(pts)[0], roi, (64, 64)))


def test_dataset_round_trips_through_npz(gl_context, tmp_path):
    shards = make_dataset(5, seed=3, size=48, path=tmp_path / "ds", shard_size=2)
    assert [p.name for p in shards] == ["shard_00000.npz", "shard_00001.npz", "shard_00002.npz"]
    ds = load_dataset(tmp_path / "ds")
    assert len(ds) == 5 and ds.images.shape == (5, 48, 48, 3) and ds.keypoints.shape == (5, 12, 2)
    assert ds.info["seed"] == 3 and ds.info["split"] == "train"
    again = random_training_sample(sample_rng(3, 3), 48)
    assert np.array_equal(ds.images[3], again.image)
    assert np.allclose(ds.keypoints[3], again.keypoints, atol=1e-4)
    assert np.array_equal(ds.visible[3], again.visible) and np.array_equal(ds.self_occluded[3], again.self_occluded)
    assert np.allclose(ds.rois[3], again.roi) and ds.meta[3] == again.meta
    assert np.allclose(ds.wireframes[3], again.wireframe.vehicle_p_keypoints)
    single = load_dataset(shards[1])
    assert len(single) == 2 and np.array_equal(single.images[1], ds.images[3])


def test_a_custom_split_draws_only_its_vehicles(gl_context, tmp_path):
    from dataclasses import replace

    from vfactor.render.dataset import TRAIN

    library_only = replace(TRAIN, name="library_only", library_probability=1.0)
    make_dataset(3, seed=4, size=32, path=tmp_path / "lib", split=library_only)
    ds = load_dataset(tmp_path / "lib")
    assert ds.info["split"] == "library_only" and ds.info["split_spec"]["library_probability"] == 1.0
    assert all(m["source"] in TRAIN.library_models for m in ds.meta), [m["source"] for m in ds.meta]
    no_library = replace(TRAIN, library_probability=0.0)
    make_dataset(3, seed=4, size=32, path=tmp_path / "rest", split=no_library)
    assert not any(m["source"] in TRAIN.library_models for m in load_dataset(tmp_path / "rest").meta)


def test_vehicles_cut_by_the_image_can_be_framed_from_their_clipped_box(gl_context):
    """clipped_box_probability: a target the image border cuts is cropped from its box clipped to the image and grown
    as the detector grows such boxes; its keypoints beyond that crop are not in it (in_crop), those inside are."""
    from vfactor.heatmaps import extend_clipped_roi
    from vfactor.render.dataset import SampleOptions

    options = SampleOptions(edge_probability=1.0, clipped_box_probability=1.0, jitter=0.0, margin=(0.2, 0.2))
    samples = [random_training_sample(sample_rng(7, i), 64, options=options) for i in range(6)]
    cut = [s for s in samples if s.meta["box_clipped"]]
    assert cut, [s.meta["box"] for s in samples]
    for s in cut:
        width, height = options.image_size
        box = np.array(s.meta["box"])
        clipped = np.clip(box, -0.5, [width - 0.5, height - 0.5] * 2)
        assert np.any(clipped != box)  # the image cuts it, and the box is the clipped one grown beyond the border
        assert extend_clipped_roi(clipped, width, height) == pytest.approx(tuple(box))
        assert np.allclose(roi_from_box(np.array(s.meta["box"]), 0.2, True), s.roi)
    default = random_training_sample(sample_rng(7, 0), 64)
    assert default.meta["box_clipped"] is False


def test_real_roofs_stand_above_the_window_tops_and_move_no_keypoint(gl_context):
    from vfactor.box import default_box_model
    from vfactor.render.dataset import SampleOptions, roof_height
    from vfactor.wireframe import PRESETS, Wireframe

    van = library_vehicle("citroen_jumper_l3h3")
    assert roof_height(van.wireframe, van.id, 0.34) == pytest.approx(van.dimensions.height - 0.34)
    lower = Wireframe(van.wireframe.vehicle_p_keypoints * [1.0, 1.0, 0.9])  # stretched: the roof follows
    offset = van.dimensions.height - 0.34 - van.wireframe.vehicle_p_keypoints[8:, 2].max()
    assert roof_height(lower, van.id, 0.34, follow_window_tops=True) == pytest.approx(
        lower.vehicle_p_keypoints[8:, 2].max() + offset, abs=0.02)
    preset = PRESETS["bmw_x5"].wireframe()
    top = max(preset.vehicle_p_keypoints[[8, 9], 2].mean(), preset.vehicle_p_keypoints[[10, 11], 2].mean())
    assert roof_height(preset, "bmw_x5", 0.35) == pytest.approx(top + default_box_model().mean["any"][2])
    for i in range(4):  # the same draws; the roof only raises the vehicle's box
        low = random_training_sample(sample_rng(9, i), 64, options=SampleOptions(real_roofs=False))
        high = random_training_sample(sample_rng(9, i), 64)  # the default
        assert high.meta["source"] == low.meta["source"]
        assert high.meta["box"][1] < low.meta["box"][1] and high.meta["box"][3] == pytest.approx(low.meta["box"][3])


def test_library_type_weights_set_how_often_each_body_type_is_drawn(gl_context, tmp_path):
    from dataclasses import replace

    vans_only = replace(TRAIN, library_probability=1.0,
                        library_type_weights=tuple((t, 0.0) for t in BODY_TYPES if t != "van"))
    make_dataset(4, seed=4, size=32, path=tmp_path / "vans", split=vans_only)
    sources = [m["source"] for m in load_dataset(tmp_path / "vans").meta]
    assert all(library_vehicle(s).body_type == "van" for s in sources), sources
    p = replace(TRAIN, library_type_weights=(("van", 3.0),)).library_draw_probabilities()
    vans = np.array([library_vehicle(m).body_type == "van" for m in TRAIN.library_models])
    assert p.sum() == pytest.approx(1.0)
    assert np.allclose(p[vans], 3 * p[~vans][0]) and np.allclose(p[~vans], p[~vans][0])
    assert TRAIN.library_draw_probabilities() is None  # the default: every model as often, the draws as before
    with pytest.raises(ValueError, match="unknown body type 'truck'"):
        replace(TRAIN, library_type_weights=(("truck", 2.0),))
    with pytest.raises(ValueError, match="weights >= 0"):
        replace(TRAIN, library_type_weights=(("van", -1.0),))


def test_shape_stretch_draws_shapes_between_and_beyond_the_models_within_the_hwc_bounds():
    from dataclasses import replace

    from vfactor.render.dataset import random_vehicle
    from vfactor.sim.vehicles import within_hwc_bounds

    stretched, plain = replace(TRAIN, shape_stretch=0.12), np.random.default_rng(3)
    rng = np.random.default_rng(3)
    ratios = []
    for _ in range(60):
        wf, _, source = random_vehicle(rng, stretched)
        assert within_hwc_bounds(wf)
        p = wf.vehicle_p_keypoints
        assert np.allclose(p[0::2, 1], -p[1::2, 1])  # still left/right symmetric
        if source in library_ids():  # its length against the model's (within the 3 cm jitter)
            q = library_vehicle(source).wireframe.vehicle_p_keypoints
            ratios.append(np.ptp(p[:, 0]) / np.ptp(q[:, 0]))
    assert len(ratios) >= 10 and min(ratios) < 0.96 and max(ratios) > 1.04 and 0.86 < min(ratios)
    assert max(ratios) < 1.14
    # without a stretch the draws are those of before, to the bit
    assert random_vehicle(plain, TRAIN)[2] == random_vehicle(np.random.default_rng(3), replace(TRAIN))[2]
    with pytest.raises(ValueError, match="shape_stretch"):
        replace(TRAIN, shape_stretch=0.6)


def test_command_line(gl_context, tmp_path, capsys):
    from vfactor.render.dataset import main

    assert main([str(tmp_path / "cli"), "--n", "2", "--size", "32", "--held-out", "--seed", "9"]) == 0
    ds = load_dataset(tmp_path / "cli")
    assert len(ds) == 2 and ds.info["split"] == "held_out" and ds.images.shape[1:] == (32, 32, 3)
    assert "wrote 1 shard" in capsys.readouterr().err
