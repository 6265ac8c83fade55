"""Experiment: the shipped keypoint network fine-tuned on rendered buses, on the CPU; PCK on buses it never saw.

The library's buses are split as the light vehicles are (:func:`vfactor.render.dataset.library_split`: the even
positions train, the odd ones are held out). The training crops are :data:`vfactor.render.dataset.TRAIN`'s with
the even-half buses added (a library vehicle in 40 % of the crops, a bus drawn three times as often as a light
model: about 30 % of the library's crops), roofs at the window tops as the shipped weights were trained; the
validation crops :data:`~vfactor.render.dataset.HELD_OUT`'s with the odd-half buses. The shipped weights and the
fine-tuned ones are scored (PCK@0.1, visible and self-occluded keypoints) on two test sets of held-out crops: the
usual one (light vehicles) and one of the odd-half buses alone.

Run: ``python benchmarks/bus_finetune.py [--lr LR] [--epochs N] [--crops N] [--out DIR]`` (defaults 5e-4, 6,
3000, runs/bus_finetune; about 5 min on 2 cores: rendering 1.3 min, epochs about 30 s). Needs the ``net`` and
``render`` extras.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path


def main(argv=None) -> dict:
    import torch

    from vfactor.net.data import as_dataset
    from vfactor.net.model import default_weights_path, load_weights
    from vfactor.net.train import TrainConfig, evaluate_model, train
    from vfactor.render.dataset import HELD_OUT, TRAIN, SampleOptions, load_dataset, make_dataset
    from vfactor.vehicle_library import library_ids

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lr", type=float, default=5e-4)
    parser.add_argument("--epochs", type=int, default=6)
    parser.add_argument("--crops", type=int, default=3000)
    parser.add_argument("--out", default="runs/bus_finetune")
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    out = Path(args.out)
    buses = library_ids("bus")
    trained_on, held_out = tuple(buses[0::2]), tuple(buses[1::2])
    weights = (("bus", 3.0),)
    splits = {  # name -> (split, crops, seed, held-out bins)
        "train": (dataclasses.replace(TRAIN, library_models=TRAIN.library_models + trained_on,
                                      library_probability=0.4, library_type_weights=weights), args.crops, 41, False),
        "val": (dataclasses.replace(HELD_OUT, library_models=HELD_OUT.library_models + held_out,
                                    library_type_weights=weights), 400, 41, True),
        "test_light": (HELD_OUT, 800, 43, True),
        "test_bus": (dataclasses.replace(HELD_OUT, library_models=held_out, library_probability=1.0), 400, 43, True),
    }
    t0 = time.perf_counter()
    paths = {}
    for name, (split, crops, seed, held) in splits.items():
        paths[name] = out / "data" / name
        if not any(paths[name].glob("*.npz")):
            make_dataset(crops, seed=seed, size=96, path=paths[name], held_out=held, workers=2, split=split,
                         options=SampleOptions(real_roofs=False))
    print(f"rendered in {time.perf_counter() - t0:.0f} s; buses trained on {', '.join(trained_on)}; held out "
          f"{', '.join(held_out)}", flush=True)
    shipped, config = load_weights(default_weights_path(), with_config=True)
    fields = {k: v for k, v in config["train"].items() if k in TrainConfig.__dataclass_fields__}
    run = train(TrainConfig.from_dict({**fields, "epochs": args.epochs, "lr": args.lr, "seed": 21, "num_threads": 2}),
                as_dataset(load_dataset(paths["train"])), load_dataset(paths["val"]), out_dir=out / "run",
                progress=False, init_weights=str(default_weights_path()))
    tuned = load_weights(run.best_weights_path or run.weights_path)
    scores = {name: {test: evaluate_model(model, load_dataset(paths[test])) for test in ("test_light", "test_bus")}
              for name, model in (("shipped", shipped), ("fine-tuned", tuned))}
    print("| weights | light vehicles: PCK visible / self-occluded | held-out buses |\n| --- | --- | --- |")
    for name, by_test in scores.items():
        print(f"| {name} | " + " | ".join(f"{by_test[t]['pck_visible']:.3f} / {by_test[t]['pck_self_occluded']:.3f}"
                                         for t in ("test_light", "test_bus")) + " |")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return scores


if __name__ == "__main__":
    main()
