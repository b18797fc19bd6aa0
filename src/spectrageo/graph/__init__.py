"""Graphs over vertices and points: adjacency, k-rings, kNN/radius graphs and Laplacians."""

from .adjacency import adjacency_matrix, face_adjacency, k_ring, knn, knn_graph, radius_graph
from .laplacian import (
    delta_coordinates,
    laplacian_from_adjacency,
    mesh_laplacian,
    point_cloud_laplacian,
    weighted_adjacency,
)

__all__ = [
    "adjacency_matrix",
    "delta_coordinates",
    "face_adjacency",
    "k_ring",
    "knn",
    "knn_graph",
    "laplacian_from_adjacency",
    "mesh_laplacian",
    "point_cloud_laplacian",
    "radius_graph",
    "weighted_adjacency",
]
