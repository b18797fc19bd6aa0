"""Geometry containers and per-element quantities (thesis Chapter 3)."""

from .data import Mesh, MeshAnimation, PointCloud, PointCloudSequence
from .neighbors import knn
from .pointcloud import PCANormals, pca_normals, pca_normals_eigen
from .primitives import (
    boundary_edges,
    boundary_loops,
    cotangent_weights,
    edge_lengths,
    edges,
    face_areas,
    face_centroids,
    face_normals,
    mean_curvature,
    mean_edge_length,
    vertex_areas,
    vertex_face_matrix,
    vertex_normals,
)
from .repair import (
    WELD_TOL,
    RepairReport,
    Weld,
    clean_mesh,
    degenerate_faces,
    duplicate_faces,
    is_soup,
    merge_duplicate_vertices,
    remove_unreferenced,
    unreferenced_vertices,
    weld,
)
from .topology import mesh_topology
from .update import update_vertices

__all__ = [
    "Mesh",
    "MeshAnimation",
    "PCANormals",
    "PointCloud",
    "PointCloudSequence",
    "RepairReport",
    "WELD_TOL",
    "Weld",
    "boundary_edges",
    "boundary_loops",
    "clean_mesh",
    "cotangent_weights",
    "degenerate_faces",
    "duplicate_faces",
    "edge_lengths",
    "edges",
    "face_areas",
    "face_centroids",
    "face_normals",
    "mean_curvature",
    "mean_edge_length",
    "mesh_topology",
    "is_soup",
    "knn",
    "merge_duplicate_vertices",
    "pca_normals",
    "pca_normals_eigen",
    "remove_unreferenced",
    "unreferenced_vertices",
    "update_vertices",
    "vertex_areas",
    "vertex_face_matrix",
    "vertex_normals",
    "weld",
]
