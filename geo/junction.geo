// A base block under three blocks side by side: "middle" touches three bodies (base, left,
// right), and at (1, 1) and (2, 1) three bodies meet at a point.
//
// Physical groups: bodies base, left, middle, right; contacts base_left, base_middle,
// base_right, left_middle, middle_right; boundaries floor (y = 0), left_top, middle_top,
// right_top, and sides (the outer vertical sides).
DefineConstant[ cells = 4 ];   // elements along each edge of a unit square
DefineConstant[ quads = 1 ];   // 1: quadrilaterals, 0: triangles

// points of the base (y = 0, 1) and of the top row (y = 2)
For i In {0 : 3}
  Point(1 + i) = {i, 0, 0};
  Point(11 + i) = {i, 1, 0};
  Point(21 + i) = {i, 2, 0};
EndFor
Line(1) = {1, 4};                       // floor
Line(2) = {4, 14};                      // base right side
Line(3) = {14, 13}; Line(4) = {13, 12}; Line(5) = {12, 11};   // base top, in three pieces
Line(6) = {11, 1};                      // base left side
For i In {0 : 3}
  Line(30 + i) = {11 + i, 21 + i};      // verticals of the top row
EndFor
For i In {0 : 2}
  Line(40 + i) = {21 + i, 22 + i};      // tops of the top row
EndFor
Curve Loop(1) = {1, 2, 3, 4, 5, 6};
Plane Surface(1) = {1};
Curve Loop(2) = {-5, 31, -40, -30}; Plane Surface(2) = {2};
Curve Loop(3) = {-4, 32, -41, -31}; Plane Surface(3) = {3};
Curve Loop(4) = {-3, 33, -42, -32}; Plane Surface(4) = {4};
Transfinite Curve{3, 4, 5, 30, 31, 32, 33, 40, 41, 42, 2, 6} = cells + 1;
Transfinite Curve{1} = 3 * cells + 1;
Transfinite Surface{1} = {1, 4, 14, 11};
Transfinite Surface{2, 3, 4};
If (quads)
  Recombine Surface{1, 2, 3, 4};
EndIf
Physical Surface("base") = {1};
Physical Surface("left") = {2};
Physical Surface("middle") = {3};
Physical Surface("right") = {4};
Physical Curve("base_left") = {5};
Physical Curve("base_middle") = {4};
Physical Curve("base_right") = {3};
Physical Curve("left_middle") = {31};
Physical Curve("middle_right") = {32};
Physical Curve("floor") = {1};
Physical Curve("left_top") = {40};
Physical Curve("middle_top") = {41};
Physical Curve("right_top") = {42};
Physical Curve("sides") = {2, 6, 30, 33};
