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
    * Order and counts are preserved exactly: no reader merges, drops or reorders vertices or faces
      (ground-truth pairs and animations rely on it), with one exception: triangle soups (STL, and
      any mesh whose faces share no vertex) are welded by default, merging vertices within 1e-6 of
      the bounding-box diagonal (``weld=False`` keeps the raw soup; :func:`read_with_report` says how
      many were merged). Degenerate faces, duplicate (seam) and unreferenced vertices are otherwise
      kept; repairs are explicit with :func:`spectrageo.geometry.clean_mesh`.
    * Quads and polygons are triangulated as fans ``(v0, vi, vi+1)``, each polygon's triangles in
      place, so face order follows the file; PLY face properties are repeated on a polygon's triangles.
    * Bad input raises :class:`~spectrageo.InvalidInputError` naming the file (missing file, malformed
      or truncated content, NaN coordinates, indices out of range, empty geometry, wrong shapes);
      unknown extensions raise :class:`~spectrageo.UnsupportedFormatError` listing supported ones.
      Library exceptions are caught and re-raised as these errors.
    * NaN points: an error, except in PCD files whose organized clouds use NaN for "no measurement";
      those points are dropped by default (``nan_points=``), their original indices kept in the
      ``source_index`` attribute (and in :class:`ReadReport`), so per-point outputs can be mapped
      back to every input row.
    * Every write is atomic (:func:`atomic_write`): a failure leaves no partial file and no temporary.
      Temporaries are named ``.NAME.spectrageo-tmp-XXXXXXXX.EXT`` (those of killed writes older than
      an hour are removed on the next write); an existing target keeps its permission bits, a
      symbolic link is written through to its target, and a FIFO/device or read-only target is
      refused with a clear error.
    * Hostile or corrupted files: every size a file declares (element and point counts, array
      shapes, VLRs, chunk tables, compressed and decompressed sizes) is checked against the bytes
      present and against a memory cap before anything is allocated or handed to native code
      (lazrs, python-lzf); gzip is inflated in a bounded stream. The cap is the environment
      variable ``SPECTRAGEO_MAX_BYTES`` (bytes, or with a suffix ``K M G T``: ``16G``); default: the
      smallest of 8 GiB, half the physical memory and a quarter of the address-space limit
      (``ulimit -v``). Header/body disagreements are errors (see each reader's docstring), and so
      is running out of memory on a file (``MemoryError`` becomes :class:`InvalidInputError`).
"""

from ._api import (
    ReadReport,
    read,
    read_animation,
    read_mesh,
    read_point_cloud,
    read_sequence,
    read_with_report,
    supported_formats,
    write,
)
from ._common import atomic_write

__all__ = [
    "ReadReport",
    "atomic_write",
    "read",
    "read_animation",
    "read_mesh",
    "read_point_cloud",
    "read_sequence",
    "read_with_report",
    "supported_formats",
    "write",
]
