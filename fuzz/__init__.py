"""Mutation fuzzing of sonarmap's log readers (``python -m fuzz.run_fuzz --examples N``)."""
