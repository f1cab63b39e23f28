"""``sonarmap regress --suite``: a suite of logs held to their goldens in one command.

* :mod:`.suite_file` — the suite TOML (logs, truths, configurations, tolerances), paths
  relative to the file, every mistake one line naming the file and the entry;
* :mod:`.golden_dir` — a golden directory: what it keeps, its marker, its atomic
  replacement;
* :mod:`.check` — one log on a worker: map it, compare it (or stage its new golden), draw
  what changed;
* :mod:`.run_suite` — the driver: every log on the batch's Dask workers, one outcome each;
* :mod:`.report` — the outcomes as a terminal table, Markdown and JUnit XML.

Design and evidence: docs/ci.md.
"""
