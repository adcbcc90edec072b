"""``python -m mavsysid`` runs the console script."""

from mavsysid.cli import main

raise SystemExit(main())
