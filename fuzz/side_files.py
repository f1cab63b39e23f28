"""Hostile side files and hostile numbers, through the commands that read them.

Classes (:data:`CLASSES`): a configuration (text damage, and every numeric key, nested
ones included, at hostile values and at the edges of its range; loaded by ``config``,
a sample also mapped by ``run``), a truth map (YAML keys and the PGM image, read by
``evaluate``), regress tolerances, a batch manifest, a simulate world, and every CSV
column at hostile values (``run``).

Property (:func:`run_cli`): the command exits 0 (``ok``; ``loss`` when the run recorded
lost data) or 1 with one line on stderr and no output left behind (``rejected``) — never a
traceback, never more than a CPU-time limit or :data:`MEMORY_LIMIT_BYTES` of traced
allocations (``defect``).
"""

from __future__ import annotations

import json
import math
import random
import shutil
import traceback
import tracemalloc
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from fuzz.harness import Outcome, _time_limit, _Timeout
from fuzz.mutators import Mutation, apply

TIME_LIMIT_S = 20.0
MEMORY_LIMIT_BYTES = 1 << 30  # traced Python/numpy allocations; the target is 1.5 GB RSS

# Numbers as a TOML/YAML file or a CSV field may spell them.
TOML_NUMBERS = ("nan", "inf", "-inf", "0", "-0.0", "1e-300", "-1", "1e300", "1e10", "1e12",
                "9223372036854775807", "-9223372036854775808", '"abc"', "[]", "true")
YAML_NUMBERS = (".nan", ".inf", "-.inf", "0", "-1", "1.0e-4", "1.0e300", "1e400", "1e-4",
                "5e-2", "[]", "~", "'x'", "-1.0e12", "99999999999999999999999")
CSV_NUMBERS = ("nan", "inf", "-inf", "", "0", "-0", "-1", "1e-300", "1e308", "-1e308",
               "1e23", "100000000000000000000000", "1e10", "abc", "9" * 400, "s" * 300)


@dataclass
class Case:
    """One command line over files written under ``root``; ``out`` is the output it may
    write (must be absent after a refusal)."""

    klass: str
    what: str
    argv: list[str]
    out: Path | None = None
    files: dict[Path, bytes] = field(default_factory=dict)
    # Instead of a command: a function (SonarmapError = refused, anything else a defect).
    call: Callable[[], object] | None = None


def run_cli(case: Case, time_limit_s: float = TIME_LIMIT_S) -> Outcome:
    """Run one case in this process (typer's runner) and classify it."""
    from typer.testing import CliRunner

    from cli.app import app

    for path, data in case.files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    if case.out is not None and case.out.exists():
        shutil.rmtree(case.out) if case.out.is_dir() else case.out.unlink()
    if case.call is not None:
        return _run_call(case, time_limit_s)
    tracemalloc.start()
    try:
        with _time_limit(time_limit_s):
            res = CliRunner().invoke(app, case.argv)
    except _Timeout:
        return Outcome("defect", f"{case.what}: more than {time_limit_s} s of CPU time")
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    if peak > MEMORY_LIMIT_BYTES:
        return Outcome("defect", f"{case.what}: traced memory peak {peak >> 20} MiB")
    err = res.exception
    if err is not None and not isinstance(err, SystemExit):
        frame = traceback.extract_tb(err.__traceback__)[-1]
        where = f"{Path(frame.filename).name}:{frame.lineno}"
        return Outcome("defect", f"{case.what}: {type(err).__name__} at {where}: {str(err)[:160]}")
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    if res.exit_code == 0:
        return Outcome("loss" if _lost(case.out) else "ok", peak_bytes=peak)
    if res.exit_code != 1:
        return Outcome("defect", f"{case.what}: exit {res.exit_code}: {res.output[-200:]!r}")
    if len(lines) > 1 or "Traceback" in res.stderr:
        return Outcome("defect", f"{case.what}: {len(lines)} lines on stderr: {lines[:3]!r}")
    if case.out is not None and case.out.exists() and case.argv[0] in ("run", "simulate"):
        return Outcome("defect", f"{case.what}: refused but left {case.out.name}")
    return Outcome("rejected", lines[0] if lines else res.stdout[-200:], peak_bytes=peak)


def _run_call(case: Case, time_limit_s: float) -> Outcome:
    from formats.errors import SonarmapError

    assert case.call is not None
    try:
        with _time_limit(time_limit_s):
            case.call()
    except _Timeout:
        return Outcome("defect", f"{case.what}: more than {time_limit_s} s of CPU time")
    except SonarmapError as err:
        if "\n" in str(err):
            return Outcome("defect", f"{case.what}: multi-line error {str(err)!r}")
        return Outcome("rejected", str(err))
    except Exception as err:
        frame = traceback.extract_tb(err.__traceback__)[-1]
        where = f"{Path(frame.filename).name}:{frame.lineno}"
        return Outcome("defect", f"{case.what}: {type(err).__name__} at {where}: {str(err)[:160]}")
    return Outcome("ok")


def _lost(out: Path | None) -> bool:
    metrics = out / "metrics.json" if out is not None else None
    if metrics is None or not metrics.is_file():
        return False
    return bool(json.loads(metrics.read_text()).get("input", {}).get("losses"))


# --------------------------------------------------------------------------- fixtures


@dataclass(frozen=True)
class Fixtures:
    """A tiny CSV log, a config that maps it, its run, a truth map and a small world."""

    root: Path
    log: Path
    config: Path
    run: Path
    truth_yaml: Path
    truth_pgm: Path
    world: Path


def _tiny_rows() -> list[str]:
    return ["t,x,y,yaw,sensor,range,fov,min_range,max_range,scan"] + [
        f"{0.05 * i:.3f},{0.02 * i},0,0,s{i % 2},{1.5 + 0.01 * (i % 5)},0.5,0.1,5.0,{i // 2}"
        for i in range(120)
    ]


CONFIG_TEXT = """[grid]
resolution = 0.1

[[sensors.mounts]]
name = "s0"
yaw_deg = 90.0

[[sensors.mounts]]
name = "s1"
yaw_deg = -90.0
"""

WORLD_TEXT = """name = "box"
bounds = [0.0, 0.0, 4.0, 3.0]
[[polygon]]
points = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]
[[circle]]
center = [2.0, 1.5]
radius = 0.2
"""


def build_fixtures(root: Path) -> Fixtures:
    """Write the fixtures under ``root`` (a run and a simulated truth: ~2 s)."""
    from typer.testing import CliRunner

    from cli.app import app

    root.mkdir(parents=True, exist_ok=True)
    log = root / "tiny.csv"
    log.write_text("\n".join(_tiny_rows()) + "\n")
    config = root / "tiny.toml"
    config.write_text(CONFIG_TEXT)
    run = root / "run"
    if not run.exists():
        res = CliRunner().invoke(app, ["run", str(log), "-o", str(run), "-c", str(config), "-q"])
        assert res.exit_code == 0, res.output
    world = root / "box.toml"
    world.write_text(WORLD_TEXT)
    (root / "box.waypoints.csv").write_text("x,y\n1,1\n3,1\n3,2\n")
    sim = root / "box.csv"
    if not sim.exists():
        res = CliRunner().invoke(app, ["simulate", str(world), "-o", str(sim), "-f", "csv"])
        assert res.exit_code == 0, res.output
    return Fixtures(root, log, config, run, root / "box.truth.yaml", root / "box.truth.pgm",
                    world)


# --------------------------------------------------------------------------- classes


def _text_damage(rnd: random.Random, data: bytes) -> Mutation:
    n = max(len(data), 1)
    kind = rnd.choice(("truncate", "flip", "delete", "insert", "zero_run"))
    if kind == "truncate":
        return Mutation(kind, offset=rnd.randrange(n))
    if kind == "flip":
        return Mutation(kind, offset=rnd.randrange(n), bits=(1 << rnd.randrange(8),))
    if kind == "delete":
        return Mutation(kind, offset=rnd.randrange(n), length=rnd.randint(1, 16))
    if kind == "insert":
        return Mutation(kind, offset=rnd.randrange(n), payload=rnd.choice(
            (b"\x00", b"\xff\xfe", b"\n[x]\n", b"=", b"\"", b"]", b"\n- [\n", b"9" * 400)))
    return Mutation(kind, offset=rnd.randrange(n), length=rnd.choice((1, 8, 64)))


def _set_key(text: str, key: str, value: str, sep: str) -> str:
    """``text`` with the line ``key<sep>...`` given ``value`` (added when absent)."""
    lines = text.splitlines()
    for i, ln in enumerate(lines):
        if ln.split(sep)[0].strip() == key:
            lines[i] = f"{key}{sep}{value}"
            return "\n".join(lines) + "\n"
    return "\n".join([f"{key}{sep}{value}", *lines]) + "\n"


def config_numbers(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """Every numeric key (nested tables and arrays too) at every hostile number and just
    beyond the ends of its range (``config`` loads or refuses it); then each key at both
    ends of its range mapped by ``run`` (``n`` > 0: a sample of that many)."""
    from formats.options import MountConfig, SensorsConfig
    from pipeline.config import RANGES, Config, numeric_keys

    base = Config(sensors=SensorsConfig(mounts=(MountConfig("s0"),)))
    keys = sorted({g for _, g, _ in numeric_keys(base)} | {"grid.extent"})
    runs: list[Case] = []
    for generic in keys:
        rng = RANGES[generic]
        integer = isinstance(base_value(base, generic), int)
        outside = (_beyond(rng.lo, -1), _beyond(rng.hi, 1))
        for value in [*TOML_NUMBERS, *(_spell(v, integer, -1 if i else 1)
                                       for i, v in enumerate(outside))]:
            path = fx.root / "cfg" / f"{generic}.toml"
            yield Case("config numbers", f"{generic} = {value}", ["config", "-c", str(path)],
                       files={path: _config_with(generic, value).encode()})
        inside = (_beyond(rng.lo, 1) if rng.lo_open else rng.lo,
                  _beyond(rng.hi, -1) if rng.hi_open else rng.hi)
        for i, v in enumerate(inside):
            value = _spell(v, integer, 1 if i else -1)
            path = fx.root / "cfg-run" / f"{generic}.toml"
            out = fx.root / "cfg-run-out"
            runs.append(Case("config edges (run)", f"{generic} = {value}",
                             ["run", str(fx.log), "-o", str(out), "-c", str(path), "-q"], out,
                             files={path: _config_with(generic, value).encode()}))
    yield from (rnd.sample(runs, n) if 0 < n < len(runs) else runs)


def base_value(cfg: object, generic: str) -> object:
    """The default value of a key of ``cfg`` (the first mount's or extent's for arrays)."""
    from pipeline.config import numeric_keys

    return next((v for _, g, v in numeric_keys(cfg) if g == generic), 0.0)


def _spell(v: float, integer: bool, toward: int) -> str:
    """``v`` as TOML: an integer key's value rounded toward ``-toward`` ∞ (inside stays
    inside, outside outside)."""
    if not integer:
        return repr(float(v))
    return repr(math.floor(v) if toward > 0 else math.ceil(v))


def _beyond(v: float, sign: int) -> float:
    return v + sign * max(abs(v) * 1e-3, 1e-9)


def _config_with(generic: str, value: str) -> str:
    """The fixtures' configuration (both sensors mounted) with one key set to ``value``."""
    section, _, key = generic.rpartition(".")
    mounts = '[[sensors.mounts]]\nname = "s0"\nyaw_deg = 90.0\n{extra}\n' \
             '[[sensors.mounts]]\nname = "s1"\nyaw_deg = -90.0\n'
    if section == "sensors.mounts":
        return "[grid]\nresolution = 0.1\n\n" + mounts.format(extra=f"{key} = {value}")
    if generic == "grid.extent":
        return f"[grid]\nextent = [-1.0, -5.0, {value}, 5.0]\n\n" + mounts.format(extra="")
    grid = "" if section == "grid" else "[grid]\nresolution = 0.1\n\n"
    return f"{grid}[{section}]\n{key} = {value}\n\n" + mounts.format(extra="")


def config_text(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """The effective configuration as ``sonarmap config`` prints it, damaged."""
    from pipeline.config import Config, dump_config

    data = dump_config(Config()).encode()
    for i in range(n):
        path = fx.root / "cfgtext" / f"{i}.toml"
        m = _text_damage(rnd, data)
        yield Case("config text", m.describe(), ["config", "-c", str(path)],
                   files={path: apply(data, m)})


def truth_map(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """Truth YAML keys at hostile values, the YAML damaged, the PGM damaged (header
    numbers too), each read by ``evaluate``."""
    yaml_text = fx.truth_yaml.read_text()
    pgm = fx.truth_pgm.read_bytes()
    d = fx.root / "truth"
    for key in ("resolution", "origin", "occupied_thresh", "free_thresh", "negate", "mode"):
        for value in YAML_NUMBERS:
            v = f"[{value}, 0.0, 0.0]" if key == "origin" else value
            y = d / f"{key}.yaml"
            text = _set_key(yaml_text, key, v, ": ").replace(fx.truth_pgm.name, "t.pgm")
            yield _evaluate(fx, f"truth {key}: {v}", y, {y: text.encode(), d / "t.pgm": pgm})
    headers = (b"P5\n100000 100000\n255\n", b"P5\n0 0\n255\n", b"P5\n-1 5\n255\n",
               b"P5\n99999999999999999999 1\n255\n", b"P5\n4 4\n0\n", b"P5\n4 4\n65536\n",
               b"P2\n3 1\n255\n1 2 nan\n", b"P5\n")
    for h in headers:
        y = d / "hdr.yaml"
        yield _evaluate(fx, f"truth pgm header {h[:30]!r}", y, {
            y: yaml_text.replace(fx.truth_pgm.name, "h.pgm").encode(), d / "h.pgm": h + bytes(64)})
    for i in range(n):
        m = _text_damage(rnd, pgm if i % 2 else yaml_text.encode())
        y = d / f"m{i}.yaml"
        files = {y: yaml_text.replace(fx.truth_pgm.name, f"m{i}.pgm").encode(),
                 d / f"m{i}.pgm": pgm}
        target = d / f"m{i}.pgm" if i % 2 else y
        files[target] = apply(files[target], m)
        yield _evaluate(fx, f"truth {'pgm' if i % 2 else 'yaml'} {m.describe()}", y, files)


def _evaluate(fx: Fixtures, what: str, yaml_path: Path, files: dict[Path, bytes]) -> Case:
    return Case("truth map", what, ["evaluate", str(fx.run), "--truth", str(yaml_path),
                                    "--no-report", "--json"], files=files)


TOLERANCE_KEYS = ("f1_drop", "features_rel", "mean_feature_variance_rel", "map_cells_differ",
                  "readings_used_abs")


def tolerances(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """Every tolerance key at hostile numbers, and damaged text, through ``regress``."""
    base = "".join(f"{k} = 0.5\n" for k in TOLERANCE_KEYS[:-1]) + "readings_used_abs = 0\n"
    d = fx.root / "tol"
    for key in TOLERANCE_KEYS:
        for value in TOML_NUMBERS:
            p = d / f"{key}.toml"
            yield _regress(fx, f"tolerance {key} = {value}", p,
                           _set_key(base, key, value, " = ").encode())
    for i in range(n):
        m = _text_damage(rnd, base.encode())
        p = d / f"m{i}.toml"
        yield _regress(fx, f"tolerances {m.describe()}", p, apply(base.encode(), m))


def _regress(fx: Fixtures, what: str, path: Path, data: bytes) -> Case:
    return Case("tolerances", what, ["regress", str(fx.run), "-g", str(fx.run),
                                     "--tolerances", str(path), "--json"], files={path: data})


MANIFEST_LINES = ("tiny.csv", "# comment", "missing.csv", "tiny.csv + tiny.csv",
                  "../" * 50 + "etc", "+", " + ", "\udcff", "@manifest.txt", "tiny.csv\r",
                  "", "nested/../tiny.csv", "tiny.csv + missing.csv", "\t", "box.toml")
# Path bytes the file system refuses (item 11 of issue 58, the paths): listed apart.
MANIFEST_PATH_LINES = ("x" * 5000, "\x00")


def manifest(fx: Fixtures, rnd: random.Random, n: int,
             lines: tuple[str, ...] = MANIFEST_LINES + MANIFEST_PATH_LINES) -> Iterator[Case]:
    """Batch manifests of hostile lines (garbage, long, missing, joined, NUL bytes, not
    UTF-8), read as ``batch`` reads them (discovery and output names; no mapping)."""
    from pipeline.config import Config
    from pipeline.tools.batch import find_logs, output_names

    def discover(p: Path) -> Callable[[], object]:
        return lambda: output_names(find_logs([], Config(), manifests=[p]))

    for i in range(n):
        picked = rnd.sample(lines, min(len(lines), rnd.randint(1, 4)))
        p = fx.root / f"manifest{i}.txt"
        data = "\n".join(picked).encode("utf-8", "surrogateescape")
        shown = [ln if len(ln) < 40 else f"{ln[:20]}...({len(ln)} chars)" for ln in picked]
        yield Case("manifest", f"manifest {shown!r}", [], files={p: data}, call=discover(p))


def world(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """World files with hostile numbers and damaged text, through ``simulate``."""
    d = fx.root / "worlds"
    waypoints = b"x,y\n1,1\n3,1\n3,2\n"
    for key, template in (("bounds", "[0.0, 0.0, {v}, 3.0]"), ("radius", "{v}"),
                          ("center", "[{v}, 1.5]")):
        for value in TOML_NUMBERS:
            text = WORLD_TEXT.replace(
                {"bounds": "bounds = [0.0, 0.0, 4.0, 3.0]", "radius": "radius = 0.2",
                 "center": "center = [2.0, 1.5]"}[key],
                f"{key} = {template.format(v=value)}")
            yield _simulate(fx, d, f"world {key} = {value}", text.encode(), waypoints)
    for value in CSV_NUMBERS[:12]:
        yield _simulate(fx, d, f"waypoint x = {value!r}", WORLD_TEXT.encode(),
                        f"x,y\n1,1\n{value},1\n3,2\n".encode())
    for _i in range(n):
        m = _text_damage(rnd, WORLD_TEXT.encode())
        yield _simulate(fx, d, f"world {m.describe()}", apply(WORLD_TEXT.encode(), m), waypoints)


def _simulate(fx: Fixtures, d: Path, what: str, text: bytes, waypoints: bytes) -> Case:
    w = d / "w.toml"
    out = d / "w.csv"
    return Case("world", what, ["simulate", str(w), "-o", str(out), "-f", "csv"], out,
                files={w: text, d / "w.waypoints.csv": waypoints})


SET_COLUMNS = {"poses.csv": ("t", "x", "y", "yaw"),
               "sensors.csv": ("sensor", "x", "y", "yaw", "fov", "min_range", "max_range"),
               "ranges.csv": ("t", "sensor", "range", "scan")}


def csv_numbers(fx: Fixtures, rnd: random.Random, n: int) -> Iterator[Case]:
    """Every column of both CSV layouts at every hostile value in one row, through
    ``run``; ``n`` > 0 limits the cases to a random sample of that many."""
    cases: list[Case] = []
    rows = _tiny_rows()
    header = rows[0].split(",")
    for j, col in enumerate(header):
        for value in CSV_NUMBERS:
            body = list(rows)
            fields = body[40].split(",")
            fields[j] = value
            body[40] = ",".join(fields)
            log = fx.root / "csvnum" / "log.csv"
            cases.append(_run(fx, f"csv single {col} = {value[:20]!r}", log,
                              {log: ("\n".join(body) + "\n").encode()}))
    for member, cols in SET_COLUMNS.items():
        for j, col in enumerate(cols):
            for value in CSV_NUMBERS:
                files = _csv_set(fx.root / "csvset" / "log", member, j, value)
                cases.append(_run(fx, f"csv set {member} {col} = {value[:20]!r}",
                                  fx.root / "csvset" / "log", files, layout="set"))
    yield from (rnd.sample(cases, n) if 0 < n < len(cases) else cases)


def _csv_set(d: Path, member: str, j: int, value: str) -> dict[Path, bytes]:
    poses = ["t,x,y,yaw"] + [f"{0.05 * i:.3f},{0.02 * i},0,0" for i in range(60)]
    sensors = ["sensor,x,y,yaw,fov,min_range,max_range", "s0,0.1,0,1.5708,0.5,0.1,5.0",
               "s1,-0.1,0,-1.5708,0.5,0.1,5.0"]
    ranges = ["t,sensor,range,scan"] + [f"{0.05 * i:.3f},s{i % 2},1.5,{i // 2}"
                                        for i in range(60)]
    tables = {"poses.csv": poses, "sensors.csv": sensors, "ranges.csv": ranges}
    rows = tables[member]
    fields = rows[2].split(",")
    fields[j] = value
    rows[2] = ",".join(fields)
    return {d / name: ("\n".join(t) + "\n").encode() for name, t in tables.items()}


def _run(fx: Fixtures, what: str, log: Path, files: dict[Path, bytes],
         layout: str = "single") -> Case:
    cfg = log.parent / "c.toml"
    files = dict(files)
    mounts = "" if layout == "set" else CONFIG_TEXT.split("\n\n", 1)[1]  # sensors.csv has them
    files[cfg] = (f"[input.csv]\nlayout = \"{layout}\"\n[grid]\nresolution = 0.1\n\n"
                  f"{mounts}").encode()
    out = fx.root / "csv-out"
    return Case("csv numbers", what, ["run", str(log), "-o", str(out), "-c", str(cfg), "-q"],
                out, files=files)


CLASSES: dict[str, Callable[[Fixtures, random.Random, int], Iterator[Case]]] = {
    "config numbers": config_numbers,
    "config text": config_text,
    "truth map": truth_map,
    "tolerances": tolerances,
    "manifest": manifest,
    "world": world,
    "csv numbers": csv_numbers,
}


def run_classes(root: Path, seed: int, n: int, only: str = "",
                report: Callable[[str], None] = print,
                sample: int = 0) -> dict[str, dict[str, int]]:
    """Every class (``only``: those whose name contains it), ``n`` random cases each
    where a class draws them; ``sample`` > 0: only that many cases of each class, drawn
    from all of them (a quick check). Returns per class the outcome counts and reports
    each defect."""
    import warnings

    warnings.simplefilter("ignore", RuntimeWarning)
    fx = build_fixtures(root / "fixtures")
    tally: dict[str, dict[str, int]] = {}
    for name, make in CLASSES.items():
        if only not in name:
            continue
        rnd = random.Random(f"{seed}:{name}")
        cases: list[Case] | Iterator[Case] = make(fx, rnd, n)
        if sample:
            every = list(cases)
            cases = rnd.sample(every, min(sample, len(every)))
        for case in cases:
            outcome = run_cli(case)
            counts = tally.setdefault(case.klass, {})
            counts[outcome.status] = counts.get(outcome.status, 0) + 1
            if outcome.defect:
                report(f"DEFECT [{case.klass}] {outcome.detail[:400]}")
    return tally


def table(tally: dict[str, dict[str, int]]) -> str:
    """Per class: mapped (exit 0), losses recorded, refused with one line, tracebacks
    and other defects (must be 0)."""
    head = f"{'class':<24} {'tried':>6} {'ok':>6} {'loss':>6} {'refused':>8} {'defects':>8}"
    rows = [head]
    for k, c in tally.items():
        rows.append(f"{k:<24} {sum(c.values()):>6} {c.get('ok', 0):>6} {c.get('loss', 0):>6}"
                    f" {c.get('rejected', 0):>8} {c.get('defect', 0):>8}")
    return "\n".join(rows)

