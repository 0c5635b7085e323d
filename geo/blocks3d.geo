// Two blocks in a row along x, touching on one face: the 3D check of the multiphysics solver.
//
// Physical groups (names are what the Python scripts use):
//   block_A, block_B   the two bodies (volumes)
//   contact            their common face, x = length
//   left, right        the outer ends, x = 0 and x = 2 length
//   front, bottom      the faces y = 0 and z = 0 of both blocks (for rollers)
//
// Parameters (override with load_scene(..., parameters={"size": 0.05})):
DefineConstant[ length = 0.5 ];   // block length along x [m]
DefineConstant[ width = 0.2 ];    // along y [m]
DefineConstant[ height = 0.2 ];   // along z [m]
DefineConstant[ size = 0.1 ];     // element size [m] (tetrahedra)

SetFactory("OpenCASCADE");
Box(1) = {0, 0, 0, length, width, height};
Box(2) = {length, 0, 0, length, width, height};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
Mesh.MeshSizeMin = size;
Mesh.MeshSizeMax = size;

e = 1e-6;
Physical Volume("block_A") = Volume In BoundingBox{-e, -e, -e, length + e, width + e, height + e};
Physical Volume("block_B") = Volume In BoundingBox{length - e, -e, -e, 2 * length + e, width + e, height + e};
Physical Surface("contact") = Surface In BoundingBox{length - e, -e, -e, length + e, width + e, height + e};
Physical Surface("left") = Surface In BoundingBox{-e, -e, -e, e, width + e, height + e};
Physical Surface("right") = Surface In BoundingBox{2 * length - e, -e, -e, 2 * length + e, width + e, height + e};
Physical Surface("front") = Surface In BoundingBox{-e, -e, -e, 2 * length + e, e, height + e};
Physical Surface("bottom") = Surface In BoundingBox{-e, -e, -e, 2 * length + e, width + e, e};
