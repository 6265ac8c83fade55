"""``python -m vfactor.net {train,detect} ...`` (see :mod:`vfactor.net.commands`)."""

from vfactor.net.commands import main

raise SystemExit(main())
