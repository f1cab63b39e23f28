"""The mapping methods: echo attribution with specular surfaces and a measured detection
rate (the default, ALGORITHM.md §11), with specular surfaces alone (§10), echo attribution
(§9), the paper's method (§1-5) and the classic baseline (§8). No I/O.

``make_mapper(config, grid)`` picks :class:`ForwardMapper`, :class:`SpecularMapper`,
:class:`AttributionMapper`, :class:`AndersoneMapper` or :class:`ClassicMapper` by
``config.method``; all follow the :class:`Mapper` protocol. Module map: ``forward`` (§11,
§10's passes and one E-step), ``specular`` (§10, §9's passes and two more),
``attribution`` (§9) with ``cone_kernels`` (its compiled cone loops) and
``paper_thread`` (the paper's mapper inside it, on a second thread),
``reading_features`` (eqs. 1-4), ``feature_set`` (eqs. 5-8 + spatial index),
``free_space`` (§3), ``correction`` (§4), ``occupancy`` (§5), ``grid_raster`` (shapes →
cells), ``andersone`` / ``classic`` (the mappers), ``scan_group`` (groups of scans joined
and classified once for the compiled mappers); ``kernels`` (the compiled per-scan loops, numba,
compared with the numpy modules above, which stay as the readable reference), and
``feature_store`` (the feature set the kernels work on).
"""

from __future__ import annotations

from formats.errors import ConfigError
from pipeline.config import MapperConfig
from pipeline.mapper.andersone import AndersoneMapper
from pipeline.mapper.attribution import AttributionMapper
from pipeline.mapper.classic import ClassicMapper
from pipeline.mapper.forward import ForwardMapper
from pipeline.mapper.protocol import Mapper
from pipeline.mapper.specular import SpecularMapper
from pipeline.mapper.types import GridSpec
from pipeline.methods import Method

__all__ = [
    "AndersoneMapper", "AttributionMapper", "ClassicMapper", "ForwardMapper", "Mapper", "SpecularMapper",
    "make_mapper",
]


def make_mapper(config: MapperConfig, grid: GridSpec) -> Mapper:
    """The mapper named by ``config.method`` (a :class:`~pipeline.methods.Method`)."""
    if config.method == Method.SPECULAR:
        return SpecularMapper(config, grid)
    if config.method == Method.FORWARD:
        return ForwardMapper(config, grid)
    if config.method == Method.ATTRIBUTION:
        return AttributionMapper(config, grid)
    if config.method == Method.CLASSIC:
        return ClassicMapper(config, grid)
    if config.method == Method.ANDERSONE:
        return AndersoneMapper(config, grid)
    raise ConfigError(
        f"'mapper.method' must be one of {[m.value for m in Method]}, got {config.method!r}"
    )
