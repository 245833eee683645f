"""Paper Fig. 5 (a, b): the electroelastic torus (Rb = 10, Rs = 2, H = 0.1, Mooney-Rivlin c1/c2 = 7).

(a) p_hat against u_max/Rb for E_hat in {0, 0.1538, 0.2308, 0.3077}, through the limit points;
(b) E_hat against u_max/Rb for p_hat in {0.0260, 0.0284, 0.0308, 0.0331, 0.0355}.
The limit-point maps (Fig. 5 c, d) are studies/torus_limit_maps.py.
"""

from snapmem import build_scene
from snapmem.viz.plotting import plot_family
from snapmem.study import family, parse_args, save

RB = 10.0


def main(argv=None):
    args = parse_args(__doc__, argv)
    nodes = 40 if args.quick else 200
    a = family(lambda E: build_scene("torus", nodes=nodes, E_hat=E, with_loads=("voltage",)),
               [0.0, 0.1538, 0.2308, 0.3077], "E_hat_value", "pressure", until={"u_max": 10.0})
    a["u_max_over_Rb"] = a["u_max"] / RB
    save(args, "fig5a_torus_pressure", a, nodes=nodes)
    plot_family(a, "u_max_over_Rb", "pressure", "E_hat_value", args.out / "fig5a_torus_pressure.png",
                title="Fig. 5a: torus under pressure")
    b = family(lambda p: build_scene("torus", nodes=nodes, pressure=p, with_loads=("voltage",)),
               [0.0260, 0.0284, 0.0308, 0.0331, 0.0355], "p_hat", "E_hat", until={"u_max": 10.0})
    b["u_max_over_Rb"] = b["u_max"] / RB
    save(args, "fig5b_torus_voltage", b, nodes=nodes)
    plot_family(b, "u_max_over_Rb", "E_hat", "p_hat", args.out / "fig5b_torus_voltage.png",
                title="Fig. 5b: torus under voltage")
    return a, b


if __name__ == "__main__":
    main()
