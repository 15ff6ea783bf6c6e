"""Output layer: strict JSON encoding and safe file output (every writer goes through it).

See :mod:`bwdesign.output.files` for the rules: directory outputs with a
manifest (:func:`prepare_directory`), single files with a signature line
(:func:`prepare_file`), atomic writes, nothing foreign ever replaced; the result
cache kept between runs (:class:`ResultCache`).
"""

from .files import (
    MANIFEST,
    DirectoryTarget,
    FileTarget,
    ResultCache,
    Stage,
    default_cache_dir,
    prepare_directory,
    prepare_file,
    signature_line,
)

__all__ = [
    "MANIFEST",
    "DirectoryTarget",
    "FileTarget",
    "ResultCache",
    "Stage",
    "default_cache_dir",
    "prepare_directory",
    "prepare_file",
    "signature_line",
]
