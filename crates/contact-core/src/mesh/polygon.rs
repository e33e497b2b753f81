//! Placeholder until the polygon mesher lands (replaced in the same series).
pub struct Triangulation {
    pub nodes: Vec<[f64; 2]>,
    pub triangles: Vec<[usize; 3]>,
}
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PolygonError {
    #[error("polygon domains are not available yet")]
    Unavailable,
}
pub fn triangulate(
    _: &[[f64; 2]],
    _: &[Vec<[f64; 2]>],
    _: f64,
    _: usize,
) -> Result<Triangulation, PolygonError> {
    Err(PolygonError::Unavailable)
}
