"""The examples run, and vfactor's estimate inside a larger graph matches the standalone one."""

from __future__ import annotations

import numpy as np

import vfactor
from examples import infrastructure_graph as example


def test_joint_graph_with_a_weak_link_matches_standalone():
    graph, values, sim, pose_keys = example.build_graph(range_sigma=50.0, angle_sigma=3.0)
    estimate = example.solve(graph, values)
    alone = vfactor.smooth_scene(sim.scene)
    for f, key in pose_keys.items():
        joint = estimate.atPose3(key)
        standalone = alone[f].vehicles[0].world_T_vehicle
        assert np.linalg.norm(joint.translation() - standalone.translation()) < 0.01
        assert np.degrees(np.linalg.norm(joint.rotation().logmap(standalone.rotation()))) < 0.5
    assert np.allclose(estimate.atPose3(example.RSU).matrix(), example.RSU_POSE.matrix(), atol=0.02)


def test_joint_graph_fuses_the_rsu_measurement():
    graph, values, sim, pose_keys = example.build_graph()
    estimate = example.solve(graph, values)
    errors = [np.linalg.norm(estimate.atPose3(k).translation() - sim.truth[f]["v1"].world_T_vehicle.translation())
              for f, k in pose_keys.items()]
    assert np.mean(errors) < 0.06


def test_example_main_runs(capsys):
    example.main()
    assert "joint vs standalone" in capsys.readouterr().out
