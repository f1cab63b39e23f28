"""The tools around a run: simulate, emulate, evaluate, regress, validate and batch.

They use the stages (:mod:`pipeline.stages`, :mod:`pipeline.mapper`, :mod:`pipeline.refine`);
no stage imports a tool (the import contract in ``pyproject.toml``).
"""
