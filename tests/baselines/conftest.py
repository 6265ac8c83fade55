"""Shared scenes for the baseline tests: noise-free simulated detections of the paper's three cars."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vfactor.factors.projection import KeypointObservations
from vfactor.graph import observations_from_detections
from vfactor.sim import NoiseModel, load_scenario, simulate
from vfactor.wireframe import PRESETS


def cases(sim, presets_only: bool = True):
    """(observations, truth) of every vehicle of a simulation (presets only: the HWC model is exact for them)."""
    out = []
    for f, frame in enumerate(sim.scene.frames):
        for vid in frame.vehicle_ids():
            truth = sim.truth[f][vid]
            if presets_only and truth.preset not in PRESETS:
                continue
            out.append((observations_from_detections(frame.detections_of(vid), sim.scene.cameras), truth))
    return out


@pytest.fixture(scope="session")
def noiseless_cases():
    """Lincoln MKZ, Toyota Prius and BMW X5, each seen by two cameras without noise (random confidences)."""
    return cases(simulate(load_scenario("intersection_2cam_noiseless"), seed=3, num_frames=3))


@pytest.fixture(scope="session")
def noiseless_3cam_cases():
    scenario = load_scenario("intersection_3cam")
    scenario = dataclasses.replace(scenario, noise=NoiseModel.noiseless())
    return cases(simulate(scenario, seed=5, num_frames=2))


@pytest.fixture(scope="session")
def paper_cases():
    """Ten vehicles of the paper's Webots-like scenario, with its keypoint noise."""
    return cases(simulate(load_scenario("paper_webots"), seed=0, num_frames=10))


@pytest.fixture
def lincoln(noiseless_cases):
    return noiseless_cases[0]


def keep(obs: KeypointObservations, mask) -> KeypointObservations:
    return obs.subset(np.asarray(mask, dtype=bool))


def bad_inputs(obs: KeypointObservations) -> dict[str, KeypointObservations]:
    """Observations no baseline can solve: none, three keypoints, everything at one pixel."""
    n = len(obs)
    return {
        "none": keep(obs, np.zeros(n)),
        "three_keypoints": keep(obs, np.arange(n) < 3),
        "three_keypoints_two_cameras": keep(obs, np.isin(np.arange(n), [0, 1, np.flatnonzero(obs.camera_index == 1)[0]])),
        "one_pixel": KeypointObservations(obs.cameras, obs.camera_index, obs.keypoint_index, np.full((n, 2), 300.0),
                                          obs.sqrt_information),
    }


def one_camera(obs: KeypointObservations) -> KeypointObservations:
    return keep(obs, obs.camera_index == 0)
