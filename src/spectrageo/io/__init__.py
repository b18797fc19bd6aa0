"""Reading and writing meshes, point clouds, mesh animations and point-cloud sequences.

Formats (each single-file format also gzip-compressed: ``.ply.gz``, ``.obj.gz``, ``.pcd.gz`` ...):

==========  ============================================  ==========================================
extension   read                                          write
==========  ============================================  ==========================================
``.ply``    mesh or points (plyfile), ascii/binary,       Mesh, PointCloud (binary or ascii)
            normals, colours, extra properties
``.obj``    mesh or points (meshio), polygons fanned      Mesh, PointCloud (meshio)
``.off``    mesh or points, COFF/NOFF, polygons fanned,   Mesh, PointCloud (meshio)
            ``OFF BINARY``/``NOFF BINARY`` (big-endian)
``.stl``    mesh (trimesh), corners welded unless         Mesh (binary or ascii, trimesh)
            ``weld=False``
``.pcd``    points, ascii/binary/binary_compressed,       PointCloud (``pcd_format=``)
            field names in any case (``X Y Z``)
``.xyz``    points, 3 or more columns (normals, colours,  PointCloud
            scalars), optional point-count first line
``.pts``    points (Leica/PDAL text): optional count      (read only)
            line, ``x y z [intensity] [r g b]``
``.npy``    points, (n, 3) array or structured array      PointCloud ((n, 3) array)
            with fields ``x y z``
``.las``    points (laspy, optional extra)                PointCloud
``.laz``    points (laspy + lazrs, optional extra)        PointCloud
``.npz``    MeshAnimation (``vertices``, ``faces``)       MeshAnimation, PointCloudSequence
            or PointCloudSequence (``points``
            (T, n, 3), or (N, 3) + ``counts`` (T,))
``.sgc``    mesh compressed by spectrageo.compress,       (``spectrageo compress``: lossy, takes
            decoded (order as coded)                      a method and a rate)
``.sga``    animation compressed by                       (``spectrageo compress``)
            spectrageo.compress, decoded
folder/     numbered frames (``frame_000.obj`` ...,       MeshAnimation, PointCloudSequence
            natural order) -> animation when all have     (``frame_format=".ply"`` default)
            faces (shared connectivity), else sequence
==========  ============================================  ==========================================

Policies
    * Order and counts are preserved exactly: no reader merges, drops or reorders vertices or
      faces, except that triangle soups (STL, and meshes whose faces share no vertex) are welded
      by default (``weld=False`` keeps the soup; :func:`read_with_report` counts the merges).
      Repairs are explicit (:func:`spectrageo.geometry.clean_mesh`); polygons are fanned
      ``(v0, vi, vi+1)`` in place, PLY face properties repeated on a polygon's triangles.
    * Bad input raises :class:`~spectrageo.InvalidInputError` naming the file; unknown extensions
      :class:`~spectrageo.UnsupportedFormatError` listing the supported ones.
    * NaN points are an error, except in PCD files (organized clouds), where they are dropped by
      default (``nan_points=``) and the kept rows' indices stored in ``source_index``.
    * Every write is atomic (:func:`atomic_write`): a failure leaves no partial file.
    * Every size a file declares is checked against the bytes present and a memory cap
      (``SPECTRAGEO_MAX_BYTES``, see :mod:`spectrageo.io._common`) before anything is allocated or
      handed to native code; gzip is inflated in a bounded stream; a ``MemoryError`` while
      reading becomes :class:`~spectrageo.InvalidInputError`.
    * Formats of other packages (``.sgc``, ``.sga``) register through :func:`register_format`.
"""

from ._api import register_format, supported_formats
from ._common import atomic_write
from ._read import (
    ReadReport,
    read,
    read_animation,
    read_mesh,
    read_point_cloud,
    read_sequence,
    read_with_report,
)
from ._write import write

__all__ = [
    "ReadReport",
    "atomic_write",
    "read",
    "read_animation",
    "read_mesh",
    "read_point_cloud",
    "read_sequence",
    "read_with_report",
    "register_format",
    "supported_formats",
    "write",
]
