"""Paper Fig. 4: the electroelastic balloon against the exact formula.

(a) p_hat against stretch for E_hat in {0, 0.1538, 0.2308, 0.3077} (pressure control);
(b) E_hat against stretch for p_hat in {9.5, 10.7, 11.8, 13.0, 14.2}e-3 (voltage control; the last
is above the unactuated limit pressure, so the balloon has already snapped when voltage rises).
"""

import numpy as np

from snapmem import build_scene, exact
from snapmem.viz.plotting import plot_family
from snapmem.study import family, parse_args, save


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 41 if args.quick else 201
    lam = np.linspace(1.0, 6.0, 400)
    a = family(lambda E: build_scene("balloon", nodes=nodes, E_hat=E), [0.0, 0.1538, 0.2308, 0.3077],
               "E_hat_value", "pressure", until={"stretch": 4.0})
    a["p_exact"] = exact.balloon_pressure(a["stretch"], E_hat=a["E_hat_value"])
    save(args, "fig4a_balloon_pressure", a, nodes=nodes)
    plot_family(a, "stretch", "pressure", "E_hat_value", args.out / "fig4a_balloon_pressure.png",
                exact=lambda E: (lam[lam <= 4], exact.balloon_pressure(lam[lam <= 4], E_hat=E)),
                title="Fig. 4a: balloon under pressure")
    b = family(lambda p: build_scene("balloon", nodes=nodes, pressure=p, with_loads=("voltage",)),
               [9.5e-3, 10.7e-3, 11.8e-3, 13.0e-3, 14.2e-3], "p_hat", "E_hat", until={"stretch": 6.0})
    b["E_hat_exact"] = exact.balloon_e_hat(b["stretch"].to_numpy(), b["p_hat"].to_numpy())
    save(args, "fig4b_balloon_voltage", b, nodes=nodes)
    plot_family(b, "stretch", "E_hat", "p_hat", args.out / "fig4b_balloon_voltage.png",
                exact=lambda p: (lam, exact.balloon_e_hat(lam, p)),
                title="Fig. 4b: balloon under voltage")
    return a, b


if __name__ == "__main__":
    main()
