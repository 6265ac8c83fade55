"""``python -m vfactor.render OUT --n N --seed S``: render a training dataset (see docs/rendering.md)."""

from vfactor.render.dataset import main

if __name__ == "__main__":
    raise SystemExit(main())
