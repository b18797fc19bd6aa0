"""Geometry containers and per-element quantities (thesis Chapter 3).

Names are imported from their submodules on first use, so that reading a file does not load the
solvers (scipy's sparse graphs, numba kernels) of the others.
"""

from .._plugins import lazy_exports

_EXPORTS = {
    **dict.fromkeys(("Mesh", "MeshAnimation", "PointCloud", "PointCloudSequence"), ".data"),
    "knn": ".neighbors",
    **dict.fromkeys(("PCANormals", "pca_normals", "pca_normals_eigen"), ".pointcloud"),
    **dict.fromkeys(
        (
            "boundary_edges",
            "boundary_loops",
            "cotangent_weights",
            "edge_lengths",
            "edges",
            "face_areas",
            "face_centroids",
            "face_normals",
            "mean_curvature",
            "mean_edge_length",
            "vertex_areas",
            "vertex_face_matrix",
            "vertex_normals",
        ),
        ".primitives",
    ),
    **dict.fromkeys(
        (
            "WELD_TOL",
            "RepairReport",
            "Weld",
            "clean_mesh",
            "degenerate_faces",
            "duplicate_faces",
            "is_soup",
            "merge_duplicate_vertices",
            "remove_unreferenced",
            "unreferenced_vertices",
            "weld",
        ),
        ".repair",
    ),
    "mesh_topology": ".topology",
    "update_vertices": ".update",
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
