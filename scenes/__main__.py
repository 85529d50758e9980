"""``python -m handsim.scenes``: regenerate the MJCF assets (see :mod:`handsim.scenes.generate`)."""

from handsim.scenes.generate import main

main()
