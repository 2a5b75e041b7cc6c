"""The ``mirrorcap`` command line: the core's commands plus the ones that need Blender (``bpy``).

``mirrorcap bake TAKE.c3d --head HEAD.blend -o OUT.blend [--object NAME] [--mode frames|pca] [--modes K]
[--neutral-frame N] [--head-pose REPORT.json] [--head-motion] [--report BAKE.json] [--no-blinks]
[--blink-seed S] [--blink-interval SECONDS] [--k MM]``
    bind the take to the head, run the face rig on every frame and write the head with
    shape keys to OUT.blend (atomically).

Everything else is documented in :mod:`core.cli`. ``bpy`` is imported only when a Blender
command runs, so the core commands work without it.
"""

from __future__ import annotations

import sys

from .core.cli import main as core_main


def _cmd_bake(args) -> int:
    from .core.facerig import RigSettings
    from .mirrorcap_addon.bake import run_bake

    if args.modes < 1:
        raise SystemExit("mirrorcap: error: --modes must be at least 1")
    settings = RigSettings(k=args.k, blinks=not args.no_blinks, blink_seed=args.blink_seed,
                           blink_interval_s=args.blink_interval)
    res = run_bake(args.take, args.head, args.output, object_name=args.object, mode=args.mode, n_modes=args.modes,
                   neutral_frame=args.neutral_frame, head_pose_report=args.head_pose, head_motion=args.head_motion,
                   settings=settings, report=args.report)
    if not args.quiet:
        line = (f"baked {res['frames']} frames onto {res['object']} ({res['vertices']} vertices) as "
                f"{'one shape key per frame' if res['mode'] == 'frames' else str(res['modes']) + ' PCA modes'}")
        if res["mode"] == "pca":
            line += f"; PCA error max {res['pca_max_error_mm']:.3f} mm, mean {res['pca_mean_error_mm']:.4f} mm"
        print(line)
        print(f"  {res['markers']} markers, landmarks {', '.join(res['landmarks_used'])} (RMS {res['landmark_rms_mm']:.2f} mm), "
              f"binding distance max {res['binding_distance_mm']['max']:.2f} mm")
        print(f"  {res['timings_s']['total_s']:.2f} s -> {res['output']}")
    return 0


def add_blender_commands(sub) -> None:
    bake = sub.add_parser("bake", help="bake a take onto a head as shape keys (needs bpy)",
                          description="Register TAKE.c3d to the head (landmark markers lm_<name>), run the face rig "
                                      "(regions, jaw, inner lip, blinks) and write the head with shape keys.")
    bake.add_argument("take", help="TAKE.c3d (from `mirrorcap track` or any C3D with landmark labels)")
    bake.add_argument("--head", required=True, help="HEAD.blend with a head mesh (region_*, lm_* vertex groups)")
    bake.add_argument("-o", "--output", required=True, help="OUT.blend to write")
    bake.add_argument("--object", help="the head object's name (default: the only head in the file)")
    bake.add_argument("--mode", choices=("frames", "pca"), default="frames",
                      help="frames: one shape key per frame; pca: K eigen-deformation keys (default frames)")
    bake.add_argument("--modes", type=int, default=8, help="number of PCA modes (default 8)")
    bake.add_argument("--neutral-frame", type=int, default=0, help="take frame of the neutral face (default 0)")
    bake.add_argument("--head-pose", help="REPORT.json of `mirrorcap track` (default: estimate the head motion)")
    bake.add_argument("--head-motion", action="store_true", help="key the head motion as the object's transform")
    bake.add_argument("--report", help="BAKE.json to write with the figures of the bake")
    bake.add_argument("--no-blinks", action="store_true", help="no synthetic eyelid blinks")
    bake.add_argument("--blink-seed", type=int, default=0, help="seed of the blink process (default 0)")
    bake.add_argument("--blink-interval", type=float, default=2.5, help="mean seconds between blinks (default 2.5)")
    bake.add_argument("--k", type=float, default=16.0, help="RBF kernel constant k of eq. 7.1 in mm (default 16)")
    bake.add_argument("-q", "--quiet", action="store_true")
    bake.set_defaults(func=_cmd_bake)


def main(argv=None) -> int:
    return core_main(argv, extra_commands=add_blender_commands)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
