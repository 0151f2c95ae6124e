//! stub
pub struct FaceInfo; pub enum SurfaceType {}
pub fn read_faces_json() {} pub fn sidecar_path_for() {}
