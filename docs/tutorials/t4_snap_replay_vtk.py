"""Tutorial 4: a snap in time, its replay, and its 3D export for ParaView.

The torus of the paper's C++ code (``torus_snap``) is inflated by a pressure ramped in time; past
its limit point it snaps outwards. :func:`snapmem.dynamics.driver.simulate` integrates it
(implicit BDF2, adaptive steps); the trajectory is saved (.npz), replayed as a GIF of the meridian,
and exported as the revolved surface (one .vtu per frame and a .pvd series) to open in ParaView::

    snapmem simulate torus_snap --out torus.npz
    snapmem replay torus.npz --out torus.gif
    snapmem export torus.npz --format vtk --out torus_vtk      # then: paraview torus_vtk/*.pvd

The export needs meshio (``pip install "snapmem[vtk]"``).

    python docs/tutorials/t4_snap_replay_vtk.py [--quick]
"""

from snapmem.catalog.robots import events, experiment
from snapmem.dynamics.driver import simulate

from _common import parse


def main(argv=None):
    args = parse(__doc__, argv)
    ex = experiment("torus_snap")
    t_end = 10.0 if args.quick else ex.t_end             # the snap happens at t = 5.5 s
    traj = simulate(ex.scene, ex.loads, t_end, rho=ex.rho, damping=ex.damping, q0=ex.q0, v0=ex.v0, options=ex.options)
    path = traj.save(args.out / "torus_snap.npz")
    snap = events(traj)
    print(f"{traj.meta['status']}: {traj.meta['steps']} steps, snap at t = {snap['snap']:.5g} s, "
          f"outer radius after it {snap['outer_radius']:.5g} m; saved {path}")
    if not args.quick:
        from snapmem.viz.replay import animate
        animate(traj, args.out / "torus_snap.gif", frames=60)
    from snapmem.viz.export import export       # needs meshio: pip install "snapmem[vtk]"
    series = export(path, args.out / "torus_snap_vtk", segments=16 if args.quick else 64)
    print(f"ParaView series: {series.pvd} ({len(series.membrane)} surfaces)")
    return traj, snap, series


if __name__ == "__main__":
    main()
