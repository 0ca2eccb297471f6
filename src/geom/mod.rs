//! Geometry: grid meshes, OBJ, geometry images (Eq 1, 2), Laplacian, anisotropic boundary maps.

pub mod anisotropy;
pub mod geometry_image;
pub mod laplacian;
pub mod mesh;
pub mod obj;

pub use geometry_image::Domain;
pub use mesh::GridMesh;
