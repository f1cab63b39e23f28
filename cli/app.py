"""The ``sonarmap`` command line (typer). Heavy imports live inside the commands, so that
``sonarmap --help`` is instant. Errors become exit codes only in :mod:`cli.errors`."""

from __future__ import annotations

import gc
import json
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from cli.errors import EXIT_FAILURE, handle_errors
from cli.help_words import use_words
from pipeline.methods import Method

if TYPE_CHECKING:
    from formats.storage.location import Location
    from pipeline.config import Config

app = typer.Typer(
    name="sonarmap",
    help="Probabilistic 2-D maps from sonar logs (MCAP, ROS 1 bags, ROS 2 bags, CSV).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
)

ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", "-c", help="TOML configuration file (see `sonarmap config`).",
                 show_default="built-in defaults"),
]
FormatOpt = Annotated[
    str | None,
    typer.Option("--format", "-f", help="Log format: ros1, ros2, mcap, csv.",
                 show_default="detected from the content"),
]
RangeTopicOpt = Annotated[
    list[str] | None,
    typer.Option("--range-topic", help="Range topic to map (repeatable).",
                 show_default="every sensor_msgs/Range-like topic"),
]
PoseTopicOpt = Annotated[
    str | None,
    typer.Option("--pose-topic", help="Pose topic (Odometry/PoseStamped or /tf).",
                 show_default="discovered by type"),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")]
LogsArg = Annotated[
    list[str],
    typer.Argument(help="Log file or bag directory, or its URL (s3://, gs://, az://, "
                   "http(s)://, file://); several files are one recording (split "
                   "bags, sonar and odometry bags), read as one log in time order.",
                   show_default=False, metavar="LOG..."),
]


def _locations(texts: list[str]) -> list[Location]:
    """Command-line log names as locations: URLs stay URLs (a Path would fold their //)."""
    from cli.errors import location_argument

    return [location_argument(t) for t in texts]


def _version(value: bool) -> None:
    if value:
        from pipeline import __version__

        typer.echo(f"sonarmap {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version."),
    ] = False,
    verbose: Annotated[int, typer.Option("--verbose", "-v", count=True, help="More log output.")] = 0,
) -> None:
    """sonarmap: probabilistic 2-D maps from sonar logs (MCAP, ROS 1/2 bags, CSV)."""
    level = logging.WARNING if verbose == 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)


def _load(
    config: Path | None,
    *,
    format: str | None = None,
    range_topics: list[str] | None = None,
    pose_topic: str | None = None,
    method: Method | None = None,
    resolution: float | None = None,
    refine_poses: bool = False,
) -> Config:
    """The configuration file plus command-line overrides, validated."""
    import dataclasses

    from formats.storage.options import configure
    from pipeline.config import load_config

    cfg = load_config(config)
    configure(cfg.storage)  # before any URL is opened
    inp = cfg.input
    if format:
        inp = dataclasses.replace(inp, format=format)
    if range_topics:
        inp = dataclasses.replace(inp, range_topics=tuple(range_topics))
    if pose_topic:
        inp = dataclasses.replace(inp, pose_topic=pose_topic)
    mapper = cfg.mapper
    if method is not None:
        mapper = dataclasses.replace(mapper, method=method)
    grid = cfg.grid
    if resolution is not None:
        grid = dataclasses.replace(grid, resolution=resolution)
    refine = cfg.pose_refinement
    if refine_poses:
        refine = dataclasses.replace(refine, enabled=True)
    return cfg.replace(input=inp, mapper=mapper, grid=grid, pose_refinement=refine).validate()


@app.command()
@handle_errors
def run(
    log: LogsArg,
    output: Annotated[str, typer.Option(
        "--output", "-o", help="Output directory (must not exist), or an object-store prefix "
        "(s3://bucket/prefix, gs://, az://): written last of all, its .sonarmap-output "
        "marker says the output is complete.")],
    config: ConfigOpt = None,
    format: FormatOpt = None,
    range_topic: RangeTopicOpt = None,
    pose_topic: PoseTopicOpt = None,
    method: Annotated[
        Method | None,
        typer.Option(
            "--method", "-m", metavar="METHOD", case_sensitive=True,
            help="specular (echo attribution with specular surfaces, the best maps), "
            "attribution (echo attribution without them), andersone (the paper's method as "
            "published) or classic (log-odds grid).",
            show_default="[mapper] method, specular",
        ),
    ] = None,
    resolution: Annotated[
        float | None, typer.Option("--resolution", "-r", help="Grid cell size, m.",
                                   show_default="[grid] resolution, 0.05")
    ] = None,
    compare_correction: Annotated[
        bool,
        typer.Option("--compare-correction", help="Also map without feature correction; report both."),
    ] = False,
    refine_poses: Annotated[
        bool,
        typer.Option("--refine-poses", help="Correct the odometry from the sonar data before "
                     "mapping ([pose_refinement] in the config)."),
    ] = False,
    force: Annotated[bool, typer.Option("--force", help="Replace an existing output directory.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar or summary.")] = False,
    json_out: Annotated[
        bool, typer.Option("--json", help="Print one JSON summary (outputs, counts, the paper's "
                           "metric, warnings) instead of the text summary.")
    ] = False,
) -> None:
    """Map a log: writes map.pgm/map.yaml (nav2), map.png, map.mcap (Foxglove, RViz),
    trajectory.csv (TUM), features.parquet, metrics.json, config.toml and
    report.html/report.md into OUT. With --refine-poses the poses are first corrected from
    the sonar data (trajectory.csv: the refined poses, odometry.csv: the odometry they
    started from, trajectory.png: both).

    Examples:

      sonarmap run sample_logs/office/office.mcap -o out/office

      sonarmap run robot.bag -o out/robot --range-topic /sonar --pose-topic /odom

      sonarmap run run_0.bag run_1.bag run_2.bag -o out/run

      sonarmap run sonar.mcap odom.mcap -o out/robot

      sonarmap run log.csv -o out/log --config sonarmap.toml --method classic --force

      sonarmap run drifted.mcap -o out/drifted --refine-poses
    """
    from cli.errors import location_argument
    from pipeline.run import run as run_pipeline

    logs, out = _locations(log), location_argument(output)
    cfg = _load(config, format=format, range_topics=range_topic, pose_topic=pose_topic,
                method=method, resolution=resolution, refine_poses=refine_poses)
    if _OWN_PROCESS:
        # The modules' objects (numpy's, numba's, scipy's: most of the heap) live as long
        # as the process: frozen, the run's full collections no longer walk them (an hour's
        # run made three, 0.11 s of CPU with the GIL held; two, 0.03 s, frozen).
        gc.freeze()
    if quiet or json_out:
        result = run_pipeline(logs, out, cfg, force=force, compare_correction=compare_correction)
    else:
        from cli.progress import reading_progress

        with reading_progress() as progress:
            result = run_pipeline(logs, out, cfg, force=force,
                                  compare_correction=compare_correction, progress=progress)
    m = result.metrics
    if json_out:
        typer.echo(json.dumps(_run_summary(result), indent=2))
    elif not quiet:
        pm = m.paper_metric
        typer.echo(
            f"used {m.counts['readings_mapped']} of {m.counts['readings']} readings; "
            f"{m.counts['features']} features; "
            f"mean feature variance {_fmt(pm['mean_feature_variance_m2'])} m²; "
            f"{m.map['cells_occupied']} occupied / {m.map['cells_free']} free cells"
        )
        if m.pose_refinement is not None:
            typer.echo(m.pose_refinement["summary"])
        for w in m.warnings:
            typer.echo(f"warning: {w}", err=True)
        typer.echo(f"outputs in {result.out_dir}")


def _run_summary(result: Any) -> dict[str, Any]:
    """``run --json``: where the outputs are and what the run found, in one object."""
    from formats.storage.location import Url
    from formats.writers.remote_output import remote_state
    from pipeline.stages.metrics import json_ready

    m = result.metrics
    out_dir = result.out_dir
    if isinstance(out_dir, Url):
        names = sorted(f for f in remote_state(out_dir).files if "/" not in f)
        outputs = {n: str(out_dir / n) for n in names if not n.startswith(".")}
    else:
        outputs = {p.name: str(p) for p in sorted(out_dir.iterdir())
                   if p.is_file() and not p.name.startswith(".")}
    summary: dict[str, Any] = json_ready({
        "out_dir": str(result.out_dir),
        "outputs": outputs,
        "input": {k: m.input[k] for k in ("path", "format", "duration_s") if k in m.input},
        "counts": {k: m.counts[k] for k in ("readings", "readings_used", "poses", "scans",
                                            "features") if k in m.counts},
        "dropped": {k: v for k, v in m.dropped.items() if v},
        "paper_metric": m.paper_metric,
        "map": {k: m.map[k] for k in ("cells_occupied", "cells_free", "cells_unknown",
                                      "mapped_area_m2", "resolution_m")},
        "warnings": m.warnings,
    })
    return summary


def _fmt(v: Any) -> str:
    return "n/a" if v is None or v != v else f"{v:.3g}"


@app.command()
@handle_errors
def info(
    log: LogsArg,
    config: ConfigOpt = None,
    format: FormatOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Describe a log like `ros2 bag info`, plus what sonarmap found in it.

    Examples:

      sonarmap info robot.bag

      sonarmap info rosbag2_dir --json

      sonarmap info run_0.bag run_1.bag
    """
    import dataclasses

    from formats import open_log

    cfg = _load(config, format=format)
    with open_log(_locations(log), cfg) as reader:
        li = reader.info()
    if json_out:
        typer.echo(json.dumps(dataclasses.asdict(li) | {"duration_s": li.duration_s}, indent=2))
        return
    typer.echo(_info_table(li))


def _info_table(li: Any) -> str:
    def stamp(ns: int | None) -> str:
        if ns is None:
            return "-"
        import datetime as dt

        sec, frac = divmod(ns, 1_000_000_000)  # integer ns: no float rounding in the print
        t = dt.datetime.fromtimestamp(sec, tz=dt.UTC)
        return f"{t:%Y-%m-%d %H:%M:%S}.{frac:09d} UTC ({sec}.{frac:09d})"

    lines = [
        f"Files:        {li.path}" if not li.files else f"Files:        {len(li.files)}",
        *_file_lines(li),
        f"Format:       {li.format}",
        f"Duration:     {li.duration_s:.3f} s",
        f"Start:        {stamp(li.start_ns)}",
        f"End:          {stamp(li.end_ns)}",
        f"Messages:     {li.message_count}",
        f"Topics:       {len(li.topics)}",
    ]
    width = max([len(t.name) for t in li.topics] + [5])
    for t in li.topics:
        role = f"  [{t.role}]" if t.role else ""
        lines.append(f"  {t.name:<{width}}  {t.msgtype:<40} {t.count:>8} msgs  {t.encoding}{role}")
    lines.append(f"Range topics: {', '.join(li.range_topics) or '-'}")
    lines.append(f"Pose source:  {li.pose_topic or '-'}")
    lines += [f"Note:         {n}" for n in li.notes]
    return "\n".join(lines)


def _file_lines(li: Any) -> list[str]:
    """One line per file of a recording read from several files, in time order."""
    from formats.ros.multi_source import span_text

    return [f"  {f.path}  {span_text(f.start_ns, f.end_ns)}  {f.message_count} msgs"
            for f in li.files]


@app.command()
@handle_errors
def validate(
    log: LogsArg,
    config: ConfigOpt = None,
    format: FormatOpt = None,
    range_topic: RangeTopicOpt = None,
    pose_topic: PoseTopicOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Check a log for what breaks sonar maps: stamps going backwards, clock skew, pose
    gaps, readings outside pose coverage, NaN/±Inf/negative/out-of-limit ranges (REP 117),
    sensors without a mount, stuck sensors. Exit 0 when clean (warnings allowed), 1 on errors.

    Examples:

      sonarmap validate robot.bag

      sonarmap validate log.mcap --json

      sonarmap validate sonar.bag odom.bag
    """
    from formats import open_log
    from pipeline.tools.validate import validate_log

    cfg = _load(config, format=format, range_topics=range_topic, pose_topic=pose_topic)
    with open_log(_locations(log), cfg) as reader:
        report = validate_log(reader, cfg)
    if json_out:
        typer.echo(json.dumps(report.to_dict(), indent=2))
    else:
        typer.echo(report.format_table())
    if not report.ok:
        raise typer.Exit(EXIT_FAILURE)


@app.command("config")
@handle_errors
def config_cmd(
    config: ConfigOpt = None,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write to this file instead of stdout.")
    ] = None,
) -> None:
    """Print the configuration (defaults, or a file's effective values) as commented TOML.

    Examples:

      sonarmap config > sonarmap.toml

      sonarmap config --config mine.toml
    """
    from formats.writers.atomic import atomic_write_text, check_output_file
    from pipeline.config import dump_config, load_config

    text = dump_config(load_config(config))
    if output is None:
        typer.echo(text, nl=False)
        return
    inputs = ((config, "the configuration"),) if config is not None else ()
    check_output_file(output, kind=None, force=False, inputs=inputs)
    atomic_write_text(output, text)


def _register_commands() -> None:
    """Commands that live in their own modules (each adds itself to ``app``)."""
    from cli import batch, emulate, evaluate, simulate

    simulate.register(app)
    emulate.register(app)
    evaluate.register(app)
    batch.register(app)


_register_commands()
use_words(app)  # after every command is registered


# Set by main(): the process is sonarmap's own (not a test runner's or a library user's),
# so a command may freeze the objects of its imports (gc.freeze) for the rest of it.
_OWN_PROCESS = False


def main() -> None:
    """Console entry point."""
    global _OWN_PROCESS
    _OWN_PROCESS = True
    try:
        app()
    finally:
        # The interpreter's last collection would walk every object the command made
        # (numba's too: 0.2-0.3 s after an hour's run). Once the command is done its
        # outputs are written (or rolled back); atexit hooks and finalizers still run.
        gc.freeze()


if __name__ == "__main__":  # pragma: no cover
    main()
