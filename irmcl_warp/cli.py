"""``irmcl-warp <command> [key=value ...]``: every stage as one installed command.

``irmcl-warp localize +exp=sim_office`` is ``python -m irmcl_warp.localize +exp=sim_office``: the same Hydra app,
the same settings and run folders (under ``outputs/`` of the working directory). ``irmcl-warp --help`` lists the
commands, ``irmcl-warp <command> --help`` shows one with examples, ``irmcl-warp --version`` the version.
"""

from __future__ import annotations

import difflib
import importlib
import os
import sys

from irmcl_warp import __version__

# command -> (module whose Hydra ``main`` runs it, one line on what it does, examples)
COMMANDS: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "inspect": (
        "irmcl_warp.inspect",
        "read a log, print what it holds and what looks wrong, and draw its map",
        (
            "irmcl-warp inspect                                   # the simulated office: no data needed",
            "irmcl-warp inspect data=bag data.path=run.bag data.name=mylog   # your own bag (ROS 1 file or ROS 2 folder)",
            "irmcl-warp inspect data=carmen data.path=run.clf.gz data.name=mylog",
        ),
    ),
    "slam": (
        "irmcl_warp.slam.__main__",
        "GMapping: Rao-Blackwellized particle filter SLAM over a log",
        (
            "irmcl-warp slam                                      # a map of the simulated office",
            "irmcl-warp slam data=bag data.path=run.bag data.name=mylog",
        ),
    ),
    "train": (
        "irmcl_warp.train",
        "train a neural occupancy field (NOF) on a log's scans (IR-MCL's map)",
        (
            "irmcl-warp train +exp=sim_office                     # minutes on a 2-core CPU",
            "irmcl-warp train +exp=fr079 train=fast               # a GPU, with the shared data (IRMCL_DATA)",
        ),
    ),
    "localize": (
        "irmcl_warp.localize",
        "Monte Carlo localization of a log: global or tracking",
        (
            "irmcl-warp localize +exp=sim_office mcl.num_particles=10000 device=cpu",
            "irmcl-warp localize +exp=sim_office mcl.weighting=likelihood_field localize.mode=tracking device=cpu",
        ),
    ),
    "globloc": (
        "irmcl_warp.globloc.__main__",
        "lidar + camera global localization (Gist, ORB + PnP, Scan2Map)",
        ("irmcl-warp globloc +exp=globloc_corridor",),
    ),
    "pipeline": (
        "irmcl_warp.pipeline",
        "from a raw log to a localized robot: SLAM, NOF, localization, report",
        (
            "irmcl-warp pipeline                                  # the simulator: no data needed",
            "irmcl-warp pipeline data=bag data.path=map_run.bag pipeline.path=other_run.bag",
        ),
    ),
    "worlds": (
        "irmcl_warp.worlds",
        "global localization on simulated floors nobody tuned on, with its confidence",
        ("irmcl-warp worlds +exp=worlds worlds.split=office-1001 worlds.runs=2",),
    ),
    "synthesis": (
        "irmcl_warp.synthesis",
        "scan synthesis of a trained NOF against occupancy grids",
        ("irmcl-warp synthesis +exp=fr079 train=fast",),
    ),
    "relations": (
        "irmcl_warp.relations",
        "score a log's poses against Kuemmerle et al.'s relations",
        ("irmcl-warp relations +exp=fr079",),
    ),
}

SETTINGS_HINT = (
    "settings: key=value overrides (Hydra); `irmcl-warp {cmd} --cfg job` prints every setting, "
    "`irmcl-warp {cmd} --hydra-help` Hydra's own options"
)


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = [
        f"irmcl-warp {__version__}: 2D-LiDAR localization and mapping (IR-MCL, GMapping, lidar + camera "
        "global localization) on NVIDIA Warp kernels",
        "",
        "usage: irmcl-warp <command> [key=value ...]     irmcl-warp <command> --help     irmcl-warp --version",
        "",
        "commands:",
    ]
    lines += [f"  {name:<{width}}  {about}" for name, (_, about, _) in COMMANDS.items()]
    lines += [
        "",
        "Runs land in ./outputs/<experiment>/<stage>/<run>/ of the working directory; the shared logs are "
        "read from $IRMCL_DATA.",
    ]
    return "\n".join(lines)


def command_help(name: str) -> str:
    _, about, examples = COMMANDS[name]
    return "\n".join(
        [
            f"irmcl-warp {name}: {about}",
            "",
            "examples:",
            *(f"  {e}" for e in examples),
            "",
            SETTINGS_HINT.format(cmd=name),
        ]
    )


def _say(text: str) -> None:
    """Print, and end quietly when the reader went away (``irmcl-warp --help | head``), as Python's docs advise."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        sys.exit(1)


def main(argv: list[str] | None = None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help", "help"):
        _say(usage())
        return
    if args[0] in ("-V", "--version"):
        _say(f"irmcl-warp {__version__}")
        return
    name, rest = args[0], args[1:]
    if name not in COMMANDS:
        near = difflib.get_close_matches(name, COMMANDS, n=1)
        print(
            f"error: no command '{name}'"
            + (f" (did you mean '{near[0]}'?)" if near else "")
            + f"; the commands: {', '.join(COMMANDS)}",
            file=sys.stderr,
        )
        sys.exit(2)
    if any(a in ("-h", "--help") for a in rest):
        _say(command_help(name))
        return
    rest = ["--help" if a == "--hydra-help" else a for a in rest]
    from irmcl_warp.services.cli import hydra_main

    module = importlib.import_module(COMMANDS[name][0])
    sys.argv = [f"irmcl-warp {name}", *rest]  # Hydra parses sys.argv
    hydra_main(module.main)


if __name__ == "__main__":
    main()
