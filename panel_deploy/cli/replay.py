"""``panel-deploy replay``: a recording logged to rerun, or rendered as a PNG strip."""

from __future__ import annotations

import os
import sys
import threading
from pathlib import Path

from ..errors import SceneError, shown
from ..record.analysis import read_deployment
from ..record.replay import blueprint, log_deployment
from ..record.strip import render_strip
from ..validate import write_atomic
from .args import compared_scene


def _times(text: str) -> list:
    try:
        times = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise SceneError("--at", f"expected instants in s separated by commas, got {shown(text)}") from None
    if not times:
        raise SceneError("--at", "expected at least one instant")
    return times


def replay_command(args) -> int:
    """``panel-deploy replay FILE [--save OUT.rrd | --spawn | --serve] [--png STRIP.png --at T,...]``.

    Without ``--save``, ``--serve`` or ``--png`` it opens the viewer (``--spawn``).
    ``--serve`` binds 127.0.0.1 only and runs until Ctrl-C.
    """
    at = _times(args.at) if args.png else None
    spawn = not (args.save or args.serve or (args.png and not args.spawn))
    if spawn and sys.platform.startswith("linux") and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        # rerun would try for ~20 s to reach a viewer that cannot start
        raise SceneError("--spawn", "no display for the rerun viewer (DISPLAY is not set); write "
                                    "a file with --save OUT.rrd, serve with --serve or render "
                                    "--png STRIP.png")
    d = read_deployment(args.recording, args.scene, args.namespace)
    beside = compared_scene(d, args) if args.compare else None
    if args.png:
        render_strip(d, at, args.png)
        print(f"{len(at)} frames -> {args.png}")
    if args.png and not (args.save or args.spawn or args.serve):
        d.print_notes()
        return 0
    import rerun as rr

    stream = rr.RecordingStream("panel_deploy")
    stream.set_log_time_enabled(False)  # sim_time is the one timeline
    stream.set_log_tick_enabled(False)
    if args.save:
        # in memory, then written atomically: rerun's own file sink truncates an existing
        # file first, raises on a full disk and hangs at a file size limit
        rrd = stream.binary_stream()
        stream.send_blueprint(blueprint())
    elif args.serve:
        sink = rr.GrpcServerSink(bind_ip="127.0.0.1", port=args.port)
        stream.set_sinks(sink, default_blueprint=blueprint())
    else:
        viewer = Path(sys.executable).parent / "rerun"  # the viewer rerun-sdk installs
        try:
            rr.spawn(default_blueprint=blueprint(), recording=stream,
                     executable_path=str(viewer) if viewer.exists() else None)
        except RuntimeError as e:
            raise SceneError("--spawn", f"cannot start the rerun viewer ({e}); write a file "
                                        f"with --save OUT.rrd or serve with --serve") from None
    frames = log_deployment(stream, d, beside)
    try:
        stream.flush(timeout_sec=30.0)
    except RuntimeError as e:  # a viewer that did not start (no display) or went away
        if args.serve:  # the port taken since it was checked
            raise SceneError("--serve", f"cannot serve on 127.0.0.1:{args.port} ({e}); choose "
                                        "another port with --port") from None
        raise SceneError("--spawn", f"the rerun viewer is not reachable ({e}); write a file "
                                    f"with --save OUT.rrd or serve with --serve") from None
    if args.save:
        data = rrd.read(flush=True)
        write_atomic(args.save, lambda f: f.write(data), "--save", mode="wb")
    target = args.save or ("rerun " + sink.uri if args.serve else "the rerun viewer")
    # flushed: with --serve this line (the address) must reach a pipe before the wait
    print(f"{frames} frames of {d.recording.path} -> {target}", flush=True)
    d.print_notes()
    if beside is not None:
        print(f"beside it: {beside.source} released at {beside.release:.4f} s"
              + ("" if beside.success else f" (its simulation failed: {beside.message})"),
              file=sys.stderr)
    if args.serve:
        try:
            threading.Event().wait()
        except KeyboardInterrupt:
            print("panel-deploy: stopped serving", file=sys.stderr)
    return 0
