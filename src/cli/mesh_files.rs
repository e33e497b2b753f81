//! `domain.mesh` on the command line: a gmsh file path relative to the scene file's folder
//! (or absolute), else a mesh bundled with the presets.

use contact_core::mesh::import::{import_any, MAX_FILE_BYTES};
use contact_core::mesh::AnyMesh;
use contact_core::scene::{Bundled, MeshFiles};
use std::path::PathBuf;

/// Mesh files next to a scene file.
pub struct SceneDir(pub PathBuf);

impl MeshFiles for SceneDir {
    fn load(&self, name: &str) -> Result<AnyMesh, String> {
        let path = self.0.join(name);
        let meta = match std::fs::metadata(&path) {
            Ok(m) => m,
            Err(_) if contact_core::scene::presets::bundled_mesh(name).is_some() => {
                return Bundled.load(name)
            }
            Err(e) => return Err(format!("cannot read the mesh file {}: {e}", path.display())),
        };
        if meta.len() > MAX_FILE_BYTES as u64 {
            return Err(format!(
                "the mesh file {} has {} bytes; at most {MAX_FILE_BYTES} are allowed",
                path.display(),
                meta.len()
            ));
        }
        let bytes = std::fs::read(&path)
            .map_err(|e| format!("cannot read the mesh file {}: {e}", path.display()))?;
        import_any(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }
}
