"""Command line: build or open a scene, solve, save the .blend, render a preview.

    python -m addon                          # built-in Cornell box -> out/cornell.blend, out/cornell.png
    python -m addon --scene fig1_r0.5        # a scene of sample_scenes/ (see --list)
    python -m addon --open room.blend --select-all --error 3
    blender --background room.blend --python-expr \\
        "import sys; sys.path.insert(0, '/path/to/repo'); from addon.__main__ import main; main(['--current'])"

Runs with the ``bpy`` module (pip package) or inside Blender.  The solve runs
synchronously through the same operator the panel uses (``radiosity.solve``). The command
line's parts are in ``cli/``: arguments, the run, the progress line, saving, the preview, Ctrl-C.
"""

from __future__ import annotations

import sys

from .cli.interrupt import Interrupt, exit_now
from .cli.run import main

__all__ = ["main"]

if __name__ == "__main__":
    try:
        status = main()
    except KeyboardInterrupt:  # before the run's own handler was in place
        print(Interrupt.MESSAGE, file=sys.stderr)
        status = Interrupt.STATUS
    if status in Interrupt.STATUSES:  # (Blender's own exit would take half a second more)
        exit_now(status)
    sys.exit(status)
