// Blocks in a row along x, each touching the next on one face: the 3D many-body scene.
//
// Physical groups (names are what the Python scripts use):
//   block_0 … block_{count-1}     the bodies (volumes), block_i spans [i length, (i+1) length]
//   contact_0 … contact_{count-2} contact_i between block_i and block_{i+1}
//   left, right                   the outer ends, x = 0 and x = count length
//   front, bottom                 the faces y = 0 and z = 0 of every block (for rollers)
//
// Parameters (override with load_scene(..., parameters={"size": 0.05})):
DefineConstant[ count = 4 ];      // number of blocks
DefineConstant[ length = 0.5 ];   // block length along x [m]
DefineConstant[ width = 0.2 ];    // along y [m]
DefineConstant[ height = 0.2 ];   // along z [m]
DefineConstant[ size = 0.1 ];     // element size [m] (tetrahedra)

SetFactory("OpenCASCADE");
For i In {0 : count - 1}
  Box(i + 1) = {i * length, 0, 0, length, width, height};
EndFor
BooleanFragments{ Volume{1 : count}; Delete; }{}
Mesh.MeshSizeMin = size;
Mesh.MeshSizeMax = size;

e = 1e-6;
For i In {0 : count - 1}
  Physical Volume(Sprintf("block_%g", i)) = Volume In BoundingBox{i * length - e, -e, -e, (i + 1) * length + e, width + e, height + e};
EndFor
For i In {0 : count - 2}
  Physical Surface(Sprintf("contact_%g", i)) = Surface In BoundingBox{(i + 1) * length - e, -e, -e, (i + 1) * length + e, width + e, height + e};
EndFor
Physical Surface("left") = Surface In BoundingBox{-e, -e, -e, e, width + e, height + e};
Physical Surface("right") = Surface In BoundingBox{count * length - e, -e, -e, count * length + e, width + e, height + e};
Physical Surface("front") = Surface In BoundingBox{-e, -e, -e, count * length + e, e, height + e};
Physical Surface("bottom") = Surface In BoundingBox{-e, -e, -e, count * length + e, width + e, e};
