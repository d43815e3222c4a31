"""Grain shapes, their validation, mass properties, import and stabilisation sub-mesh."""

from .mass import MassProperties, mass_properties
from .polyhedron import (
    BadFaceIndexError,
    DegenerateFaceError,
    DuplicateVerticesError,
    GeometryError,
    InconsistentOrientationError,
    InwardOrientationError,
    NonFiniteCoordinatesError,
    NonManifoldEdgeError,
    NonManifoldVertexError,
    NonPositiveVolumeError,
    OpenSurfaceError,
    Polyhedron,
    UnusedVertexError,
)
from .shapes import (
    angular_grain,
    cube,
    extruded_polygon,
    hull_polyhedron,
    l_prism,
    rotation_matrix,
    sand_grain,
    tetrahedron,
    u_prism,
)
from .submesh import SubMesh, SubMeshError, build_submesh, check_submesh
