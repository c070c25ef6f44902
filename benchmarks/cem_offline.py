"""Algorithm 3's offline phase alone, by phase: the multiscale Ω₁ of the load-path problem built ``--repeat`` times.

The cylinder load path's Ω₁ (``benchmarks/load_path.py``: model ``--model``, contrast ``--contrast``; with ``--dim
3`` the channel cube of ``benchmarks/multiscale_primal_3d.py``, h = 1/``--h``, cubes and strip of side 1/``--H``) with m =
``--layers``, l = ``--nbasis`` and ``--patch-group``: per build the fine operators, the local eigenproblems, the
patch problems (of which the LDLᵀ factorizations and their solves), the coarse operators (of which the Gram
matrices) and the whole build.  With ``--cpu`` the phase clocks read the process's CPU time (``time.perf_counter``
is replaced by ``time.process_time`` before the package is imported): on a machine shared with other jobs the
CPU times are the steadier ones.  With ``--cache DIR`` each build also writes its offline data to a fresh cache
file in DIR (``cache_save``: the write, as in a first run with ``cache_dir``).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cem_offline.py --h 256 --H 16 --patch-group 4 --repeat 3 --cpu
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cem_offline.py --dim 3 --h 16 --H 8 --layers 2 --patch-group 1 --cpu
"""

import argparse
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=int, default=256, help="1/h")
    parser.add_argument("--H", type=int, default=16, help="1/H")
    parser.add_argument("--model", type=int, default=3)
    parser.add_argument("--contrast", type=float, default=1e3)
    parser.add_argument("--layers", type=int, default=4)
    parser.add_argument("--dim", type=int, choices=(2, 3), default=2)
    parser.add_argument("--nbasis", type=int, default=None, help="local modes l (default: the rigid motions)")
    parser.add_argument("--patch-group", default="4", help="coarse cells per direction sharing a patch, or 'all'")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--cpu", action="store_true", help="phase times in CPU time")
    parser.add_argument(
        "--cache",
        default=None,
        help="write the offline data to a cache file in this directory (its cem_*.npz files removed first)",
    )
    args = parser.parse_args()
    if args.cpu:
        time.perf_counter = time.process_time
    import fenics_contact as fc
    from fenics_contact.multiscale import cem
    from fenics_contact.problem.models import get_model
    from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh

    group = args.patch_group if args.patch_group == "all" else int(args.patch_group)
    nbasis = cem.RIGID_MOTIONS if args.nbasis is None else args.nbasis
    options = cem.CEMOptions(layers=args.layers, nbasis=nbasis, patch_group=group)
    if args.dim == 3:
        problem = channels_3d(E_high=args.contrast).on(channels_3d_mesh(args.h, strip=1 / args.H, H=1 / args.H))
        name = "3D channels"
    else:
        problem = get_model(args.model, E_high=args.contrast).with_(obstacle=fc.Circle((3.0, 0.5), 2.0))
        problem = problem.on(fc.unit_square(args.h, args.H))
        name = f"model {args.model}"
    clock = "CPU" if args.cpu else "wall"
    print(
        f"{name}, contrast {args.contrast:g}, h = 1/{args.h}, H = 1/{args.H}, m = {args.layers}, "
        f"l = {options.modes(args.dim)}, patch group {args.patch_group}; {clock} times [s]"
    )
    skip = {"cache_load"} | (set() if args.cache else {"cache_save"})
    for _ in range(args.repeat):
        if args.cache:  # (a fresh file: the build writes it)
            for old in Path(args.cache).glob("cem_*.npz"):
                old.unlink()
        start = time.perf_counter()
        om = cem.build_omega1_multiscale(problem, cem=options, cache_dir=args.cache)[0]
        total = time.perf_counter() - start
        phases = {**om.times, **om.time_parts}
        print(", ".join(f"{k} {v:.2f}" for k, v in phases.items() if k not in skip) + f", total {total:.2f}")


if __name__ == "__main__":
    main()
