"""The wall time of ``ffls lights --workers N``: what runs in the main process before and between the
worker processes (docs/spheres.md, Speed: "The wall time")."""
import json
import os
import subprocess
import sys


def test_no_scipy_before_the_decoding_starts():
    """``ffls lights`` imports its command and the estimation before it forks the decoding's
    workers: SciPy (about 0.2 s of CPU, the main process alone) is imported while they decode
    (:func:`ffls.spheres.estimate.decode_photos`), not before (``ffls.spheres.ground`` imported
    ``scipy.spatial`` at its top)."""
    code = ("import json, sys; import ffls.commands.lights, ffls.spheres.estimate, ffls.spheres.detect; "
            "print(json.dumps(sorted(m for m in sys.modules if m == 'scipy' or m.startswith('scipy.'))))")
    out = subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.PIPE, text=True,
                         env=dict(os.environ, OMP_NUM_THREADS="1")).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []
