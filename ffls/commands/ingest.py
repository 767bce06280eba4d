"""``ffls ingest CAPTURE``: the capture's photos, linearised, into its chunked store (docs/scale.md)."""
from __future__ import annotations

NAME = "ingest"
HELP = "linearise a capture's photos into its chunked store (Zarr, float16, tiles x all photos, with a pyramid)"
DESCRIPTION = (
    "Read and linearise every photo (on local Dask processes, or a cluster with --scheduler), and write "
    "CAPTURE/field.zarr: float16 with the capture's checked scale, chunked as tiles x all photos, compressed, "
    "with a multi-resolution pyramid. The store records each photo's size and time and the encoding: a changed "
    "photo makes it stale, and it is rebuilt. An interrupted ingest resumes where it stopped. relight, render "
    "and view stream from the store when the photos do not fit in memory (and build it on first use).")


def add_arguments(p):
    from ffls.commands.common import add_lights_arguments, add_scale_arguments, input_path, integer, store_path

    p.add_argument("capture", type=input_path, help="capture folder (with capture.json)")
    add_lights_arguments(p)
    add_scale_arguments(p, store=False, memory=False)
    p.add_argument("--store", default=None, metavar="DIR.zarr", type=store_path,
                   help="the store (default CAPTURE/field.zarr)")
    p.add_argument("--tile", type=integer(16, 4096), default=None, metavar="PX",
                   help="tile side in pixels (default: chunks of all photos of about 8 MiB)")
    p.add_argument("--rank", type=integer(1, 100000), default=None, metavar="K",
                   help="also compute the compressed basis of K eigen-images of the accepted lights (needs lights)")
    p.add_argument("--rebuild", action="store_true", help="build again even when the store is complete and fresh")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def load_capture_for_ingest(args):
    """The capture with the encoding that its lights record (``ffls lights``), and the lights (or None)."""
    from ffls.io.capture import load_capture_and_lights

    return load_capture_and_lights(args.capture, args.lights, args.lights_map, optional=True)


def run(args) -> int:
    from ffls.commands.common import check_rank_arg, print_notes, runner_from_args
    from ffls.errors import InputError
    from ffls.store.ingest import ingest_capture

    capture, lights = load_capture_for_ingest(args)
    if args.rank is not None:
        if lights is None:
            raise InputError("--rank needs the lights (ffls lights CAPTURE, or --lights FILE)", args.capture)
        check_rank_arg(args.rank, len(lights.accepted()[0]))
    progress = not args.no_progress
    with runner_from_args(args, progress) as runner:
        rep = ingest_capture(capture, args.store, tile=args.tile, runner=runner, progress=progress,
                             rebuild=args.rebuild)
        print_notes(NAME, rep.note)
        f = rep.field
        if rep.built:
            t = rep.seconds or {}
            print(f"ffls ingest: {f.path} ({f.n} photos {f.shape[1]}x{f.shape[0]}, tiles {f.tile}, "
                  f"{len(f.levels)} levels, scale {f.scale:g}; {rep.staged} photos linearised"
                  + (f", {rep.resumed} kept from an interrupted ingest" if rep.resumed else "")
                  + f"; {sum(t.values()):.1f} s)")
        else:
            print(f"ffls ingest: {f.path} is complete and up to date ({f.n} photos)")
        if args.rank is not None:
            from ffls.relight.stream import load_or_compress_field

            idx, _ = lights.accepted()
            sc = load_or_compress_field(f, [lights.image_names[i] for i in idx], args.rank, runner=runner,
                                        progress=progress)
            print(f"ffls ingest: compressed basis of rank {sc.rank} in {f.path}/compressed/{sc.key}")
    return 0
