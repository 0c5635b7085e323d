// Two plates whose common side is drawn twice (one curve per plate), for the loader's checks.
// rows_b = rows: conforming (the two curves carry the same nodes); otherwise non-conforming.
// with stray = 1, group "stray" is a curve outside both plates: an interface group with no facets.
// with overlap = 1, group "both" holds both plates' surfaces: it overlaps the body groups.
DefineConstant[ rows = 4 ];
DefineConstant[ rows_b = 4 ];
DefineConstant[ stray = 0 ];
DefineConstant[ overlap = 0 ];
DefineConstant[ grading_b = 1 ];  // != 1: same node count, shifted nodes
Point(1) = {0, 0, 0};
Point(2) = {1, 0, 0};
Point(3) = {1, 1, 0};
Point(4) = {0, 1, 0};
Point(5) = {1, 0, 0};
Point(6) = {2, 0, 0};
Point(7) = {2, 1, 0};
Point(8) = {1, 1, 0};
Point(9) = {3, 0, 0};
Point(10) = {3, 1, 0};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 1};
Line(5) = {5, 6}; Line(6) = {6, 7}; Line(7) = {7, 8}; Line(8) = {8, 5};
Curve Loop(1) = {1, 2, 3, 4}; Plane Surface(1) = {1};
Curve Loop(2) = {5, 6, 7, 8}; Plane Surface(2) = {2};
Transfinite Curve{1, 3, 5, 7} = 3;
Transfinite Curve{2, 4} = rows + 1;
Transfinite Curve{6, 8} = rows_b + 1 Using Progression grading_b;
Transfinite Surface{1, 2};
Physical Surface("left_plate") = {1};
Physical Surface("right_plate") = {2};
Physical Curve("contact") = {2, 8};
Physical Curve("left") = {4};
Physical Curve("right") = {6};
If (stray)
  Line(9) = {9, 10};
  Physical Curve("stray") = {9};
EndIf
If (overlap)
  Physical Surface("both") = {1, 2};
EndIf
