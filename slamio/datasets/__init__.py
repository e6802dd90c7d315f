"""Importers of public datasets into the run-log format (docs/datasets.md).

Each importer is a pure function ``import_<dataset>(source_path) -> (Header, records)``;
write the result with :func:`slamio.log.write_log`. Importers may use gtsam to *find* a
file it ships (imported lazily), never to convert it: the conversion is plain Python so the
EKF side stays independent of gtsam.
"""

from slamio.datasets.victoria_park import (
    DatasetFormatError,
    default_victoria_park_path,
    import_victoria_park,
)

__all__ = ["DatasetFormatError", "default_victoria_park_path", "import_victoria_park"]
