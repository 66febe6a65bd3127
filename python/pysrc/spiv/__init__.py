"""spiv: particle image velocimetry with spike cameras.

The functions are the Rust module's (`spiv.spiv`); `spiv.dask` spreads
`spiv.flow` over a Dask cluster."""

from .spiv import *  # noqa: F401,F403
from .spiv import __all__ as _native

from ._xarray import open_flow  # noqa: E402

__all__ = list(_native) + ["open_flow"]
