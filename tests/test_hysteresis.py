"""Up, snap, down, snap back in one call, against the exact balloon."""

import pytest
from scipy.optimize import brentq

from snapmem import build_scene, exact
from snapmem.continuation.hysteresis import hysteresis


def test_balloon_hysteresis_loop_lands_on_the_exact_branches():
    loop = hysteresis(build_scene("balloon", nodes=41))
    assert loop.status == "loop closed" and loop.closed
    assert list(loop.table["segment"].unique()) == ["loading", "after snap", "unloading", "after snap back"]
    snap, back = loop.snaps.iloc[0], loop.snaps.iloc[1]
    (lam_max, p_max), (lam_min, p_min) = exact.balloon_extrema()[:2]
    assert snap["control_at_limit"] == pytest.approx(p_max, rel=2e-3) and snap["at_rest"]
    assert back["control_at_limit"] == pytest.approx(p_min, rel=2e-3) and back["at_rest"]
    far = brentq(lambda l: exact.balloon_pressure(l) - snap["control_settled"], lam_min, 10.0)
    near = brentq(lambda l: exact.balloon_pressure(l) - back["control_settled"], 1.0, lam_max)
    assert snap["stretch_after"] == pytest.approx(far, rel=5e-3)          # came to rest on the far branch
    assert back["stretch_after"] == pytest.approx(near, rel=5e-3)         # and back on the near one
    assert loop.table["pressure"].iloc[-1] == pytest.approx(0.0, abs=1e-12)
