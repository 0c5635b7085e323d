// Two plates side by side in thermal contact: Ramadane et al. (2005), figure 2.
//
// Physical groups (names are what the Python scripts use):
//   plate_A, plate_B      the two bodies (surfaces)
//   contact               their common side, x = length (curve)
//   left, right           the outer ends, x = 0 and x = 2 length
//   bottom, top           the long sides of both plates
//
// Parameters (override with load_scene(..., parameters={"layers": 8})):
DefineConstant[ layers = 4 ];     // element layers across each plate (along x)
DefineConstant[ rows = 4 ];       // element rows along the contact (along y)
DefineConstant[ length = 1.0 ];   // plate length along x [m]
DefineConstant[ height = 1.0 ];   // plate height along y [m]
DefineConstant[ quads = 1 ];      // 1: quadrilaterals, 0: triangles

Point(1) = {0, 0, 0};
Point(2) = {length, 0, 0};
Point(3) = {2 * length, 0, 0};
Point(4) = {2 * length, height, 0};
Point(5) = {length, height, 0};
Point(6) = {0, height, 0};

Line(1) = {1, 2};   // bottom of A
Line(2) = {2, 3};   // bottom of B
Line(3) = {3, 4};   // right end
Line(4) = {4, 5};   // top of B
Line(5) = {5, 6};   // top of A
Line(6) = {6, 1};   // left end
Line(7) = {2, 5};   // contact

Curve Loop(1) = {1, 7, 5, 6};
Plane Surface(1) = {1};
Curve Loop(2) = {2, 3, 4, -7};
Plane Surface(2) = {2};

Transfinite Curve{1, 2, 4, 5} = layers + 1;
Transfinite Curve{3, 6, 7} = rows + 1;
Transfinite Surface{1, 2};
If (quads)
  Recombine Surface{1, 2};
EndIf

Physical Surface("plate_A") = {1};
Physical Surface("plate_B") = {2};
Physical Curve("contact") = {7};
Physical Curve("left") = {6};
Physical Curve("right") = {3};
Physical Curve("bottom") = {1, 2};
Physical Curve("top") = {4, 5};
