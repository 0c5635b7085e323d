// A chain of bodies side by side, each touching the next: bodies body_0 ... body_<n-1>,
// contacts contact_0 ... contact_<n-2> (contact_i between body_i and body_{i+1}).
//
// Physical groups: body_<i> (surfaces), contact_<i> (curves), left (x = 0), right (the far
// end), bottom and top (the long sides of every body).
//
// Parameters (override with load_scene(..., parameters={...})):
DefineConstant[ bodies = 8 ];      // number of bodies
DefineConstant[ layers = 4 ];      // element layers across each body (along x)
DefineConstant[ rows = 4 ];        // element rows along the contacts (along y)
DefineConstant[ width = 1.0 ];     // body width along x [m]
DefineConstant[ height = 1.0 ];    // height along y [m]
DefineConstant[ quads = 1 ];       // 1: quadrilaterals, 0: triangles

For i In {0 : bodies}
  Point(2 * i + 1) = {i * width, 0, 0};
  Point(2 * i + 2) = {i * width, height, 0};
  Line(i + 1) = {2 * i + 1, 2 * i + 2};                // vertical line at x = i width
  Transfinite Curve{i + 1} = rows + 1;
EndFor
For i In {0 : bodies - 1}
  Line(1000 + i) = {2 * i + 1, 2 * i + 3};             // bottom of body i
  Line(2000 + i) = {2 * i + 4, 2 * i + 2};             // top of body i
  Transfinite Curve{1000 + i, 2000 + i} = layers + 1;
  Curve Loop(i + 1) = {1000 + i, i + 2, 2000 + i, -(i + 1)};
  Plane Surface(i + 1) = {i + 1};
  Transfinite Surface{i + 1};
  If (quads)
    Recombine Surface{i + 1};
  EndIf
  Physical Surface(Sprintf("body_%g", i)) = {i + 1};
EndFor
For i In {1 : bodies - 1}
  Physical Curve(Sprintf("contact_%g", i - 1)) = {i + 1};
EndFor
Physical Curve("left") = {1};
Physical Curve("right") = {bodies + 1};
Physical Curve("bottom") = {1000 : 1000 + bodies - 1};
Physical Curve("top") = {2000 : 2000 + bodies - 1};
