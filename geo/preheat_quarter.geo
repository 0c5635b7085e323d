// Coke bed preheating of a Hall–Héroult cell: the 3D quarter of the slice of
// geo/preheat_slice.geo. Half the cell's width along one cathode block (x from the centre line
// to the shell) and half the block's width (y from the bar's middle plane, a symmetry plane,
// to the block's side, the plane of symmetry between two blocks). The same bodies and
// dimensions as the 2D slice (see its header for the sources), with their real widths: block
// 0.48 m (half: 0.24), slot 0.2 m (half: 0.1; straight sides, the V of the slot scene left
// out), bar 0.16 m (half: 0.08); the anode and the coke bed as wide as the block; three stubs
// of 0.18 m × 0.09 m on each anode's top against y = 0 (half stubs).
//
// Physical groups (names are what the Python scripts use):
//   anode, coke, block, cast_iron, bar, paste     the bodies
//   anode_coke, coke_block                        anode / bed, bed / block
//   slot_side, slot_top                           cast iron / block (y = 0.1; z = 0.176)
//   bar_side, bar_top                             bar / cast iron (y = 0.08; z = 0.16)
//   block_paste, iron_paste, bar_paste            ramming paste / block, cast iron, bar
//   stubs, anode_cover, anode_sides, coke_sides, block_top, bottom, paste_top, sidewall,
//   bar_surface, bar_end                          as in the 2D slice
//   symmetry                                      x = 0 (the block)
//   symmetry_y                                    y = 0, the bar's middle plane (every body)
//   block_side                                    y = 0.24, the plane between two blocks
//                                                 (block, paste, coke bed, anode); both
//                                                 symmetry planes: no flux, and u_y = 0
//
// Parameters (override with load_scene(..., parameters={"size": 0.1})):
DefineConstant[ size = 0.12 ];      // element size away from the contacts [m]
DefineConstant[ fine = 0.03 ];      // element size on the contacts [m]
DefineConstant[ coke = 0.02 ];      // coke bed thickness [m]

SetFactory("OpenCASCADE");
half_length = 3.67 / 2;  width = 0.24;  height = 0.48;
slot_h = 0.176;  slot_w = 0.1;  bar_h = 0.16;  bar_w = 0.08;
x0 = 0.1;  bar_end = x0 + 2.175;
anode_x0 = 0.1;  anode_x1 = anode_x0 + 1.55;  anode_h = 0.6;
paste_w = 0.25;  stub_l = 0.18;  stub_w = 0.09;
y_bed = height + coke;  y_top = y_bed + anode_h;
e = 1e-6;

Box(1) = {0, 0, 0, half_length, width, height};                              // block + slot
Box(2) = {0, 0, 0, half_length, slot_w, slot_h};                             // the slot
Box(3) = {x0, 0, 0, bar_end - x0, bar_w, bar_h};                             // bar
Box(4) = {half_length, 0, 0, paste_w, width, height};                        // paste + bar
Box(5) = {anode_x0, 0, height, anode_x1 - anode_x0, width, coke};            // coke bed
Box(6) = {anode_x0, 0, y_bed, anode_x1 - anode_x0, width, anode_h};          // anode
block[] = BooleanDifference{ Volume{1}; Delete; }{ Volume{2}; };
iron = newv;
Box(iron) = {x0, 0, 0, half_length - x0, slot_w, slot_h};
Recursive Delete{ Volume{2}; }
// the stubs' footprints on the anode's top
pitch = (anode_x1 - anode_x0) / 3;
For i In {0 : 2}
  stub[i] = news;
  Rectangle(stub[i]) = {anode_x0 + (i + 0.5) * pitch - stub_l / 2, 0, y_top, stub_l, stub_w};
EndFor
BooleanFragments{ Volume{block[], iron, 3, 4, 5, 6}; Delete; }{ Surface{stub[]}; Delete; }

bar[] = Volume In BoundingBox{x0 - e, -e, -e, bar_end + e, bar_w + e, bar_h + e};
slot_fill[] = Volume In BoundingBox{x0 - e, -e, -e, half_length + e, slot_w + e, slot_h + e};
iron[] = slot_fill[];
iron[] -= bar[];
paste_all[] = Volume In BoundingBox{half_length - e, -e, -e, half_length + paste_w + e, width + e, height + e};
paste[] = paste_all[];
paste[] -= bar[];
carbon[] = Volume In BoundingBox{-e, -e, -e, half_length + e, width + e, height + e};
carbon[] -= slot_fill[];
carbon[] -= bar[];
Physical Volume("block") = carbon[];
Physical Volume("cast_iron") = iron[];
Physical Volume("bar") = bar[];
Physical Volume("paste") = paste[];
Physical Volume("coke") = Volume In BoundingBox{anode_x0 - e, -e, height - e, anode_x1 + e, width + e, y_bed + e};
Physical Volume("anode") = Volume In BoundingBox{anode_x0 - e, -e, y_bed - e, anode_x1 + e, width + e, y_top + e};

// Surfaces on a plane x = const, y = const or z = const, within bounds.
Macro PlaneX  // xp, ya, yb, za, zb
  found[] = Surface In BoundingBox{xp - e, ya - e, za - e, xp + e, yb + e, zb + e};
Return
Macro PlaneY  // yp, xa, xb, za, zb
  found[] = Surface In BoundingBox{xa - e, yp - e, za - e, xb + e, yp + e, zb + e};
Return
Macro PlaneZ  // zp, xa, xb, ya, yb
  found[] = Surface In BoundingBox{xa - e, ya - e, zp - e, xb + e, yb + e, zp + e};
Return

zp = y_bed; xa = anode_x0; xb = anode_x1; ya = 0; yb = width; Call PlaneZ;
Physical Surface("anode_coke") = found[];
zp = height; Call PlaneZ;
Physical Surface("coke_block") = found[];
yp = slot_w; xa = x0; xb = half_length; za = 0; zb = slot_h; Call PlaneY;
Physical Surface("slot_side") = found[];
zp = slot_h; ya = 0; yb = slot_w; Call PlaneZ;
Physical Surface("slot_top") = found[];
yp = bar_w; za = 0; zb = bar_h; Call PlaneY;
Physical Surface("bar_side") = found[];
zp = bar_h; ya = 0; yb = bar_w; Call PlaneZ;
Physical Surface("bar_top") = found[];
xp = half_length; ya = 0; yb = width; za = 0; zb = height; Call PlaneX;
ends[] = found[];
ya = 0; yb = slot_w; za = 0; zb = slot_h; Call PlaneX;
slot_end[] = found[];
yb = bar_w; zb = bar_h; Call PlaneX;
bar_cut[] = found[];
ends[] -= slot_end[];
slot_end[] -= bar_cut[];
Physical Surface("block_paste") = ends[];
Physical Surface("iron_paste") = slot_end[];
yp = bar_w; xa = half_length; xb = half_length + paste_w; za = 0; zb = bar_h; Call PlaneY;
wrap[] = found[];
zp = bar_h; ya = 0; yb = bar_w; Call PlaneZ;
wrap[] += found[];
Physical Surface("bar_paste") = wrap[];

stubs[] = {};
For i In {0 : 2}
  zp = y_top; xa = anode_x0 + (i + 0.5) * pitch - stub_l / 2; xb = xa + stub_l;
  ya = 0; yb = stub_w; Call PlaneZ;
  stubs[] += found[];
EndFor
Physical Surface("stubs") = stubs[];
zp = y_top; xa = anode_x0; xb = anode_x1; ya = 0; yb = width; Call PlaneZ;
cover[] = found[];
cover[] -= stubs[];
Physical Surface("anode_cover") = cover[];
sides[] = {};
xp = anode_x0; ya = 0; yb = width; za = y_bed; zb = y_top; Call PlaneX;
sides[] += found[];
xp = anode_x1; Call PlaneX;
sides[] += found[];
Physical Surface("anode_sides") = sides[];
sides[] = {};
xp = anode_x0; za = height; zb = y_bed; Call PlaneX;
sides[] += found[];
xp = anode_x1; Call PlaneX;
sides[] += found[];
Physical Surface("coke_sides") = sides[];
bare[] = {};
zp = height; xa = 0; xb = anode_x0; ya = 0; yb = width; Call PlaneZ;
bare[] += found[];
xa = anode_x1; xb = half_length; Call PlaneZ;
bare[] += found[];
Physical Surface("block_top") = bare[];
xp = 0; ya = 0; yb = width; za = 0; zb = height; Call PlaneX;
Physical Surface("symmetry") = found[];
yp = 0; xa = 0; xb = bar_end; za = 0; zb = y_top; Call PlaneY;
Physical Surface("symmetry_y") = found[];
yp = width; xa = 0; xb = half_length + paste_w; Call PlaneY;
Physical Surface("block_side") = found[];
zp = 0; xa = 0; xb = half_length + paste_w; ya = 0; yb = width; Call PlaneZ;
Physical Surface("bottom") = found[];
zp = height; xa = half_length; xb = half_length + paste_w; Call PlaneZ;
Physical Surface("paste_top") = found[];
xp = half_length + paste_w; ya = 0; yb = width; za = 0; zb = height; Call PlaneX;
wall[] = found[];
ya = 0; yb = bar_w; za = 0; zb = bar_h; Call PlaneX;
wall[] -= found[];
Physical Surface("sidewall") = wall[];
out[] = {};
yp = bar_w; xa = half_length + paste_w; xb = bar_end; za = 0; zb = bar_h; Call PlaneY;
out[] += found[];
zp = bar_h; ya = 0; yb = bar_w; Call PlaneZ;
out[] += found[];
zp = 0; Call PlaneZ;
out[] += found[];
Physical Surface("bar_surface") = out[];
xp = bar_end; ya = 0; yb = bar_w; za = 0; zb = bar_h; Call PlaneX;
Physical Surface("bar_end") = found[];

// Sizes: fine on the coke bed and the slot, coarse away from them.
Field[1] = Box;
Field[1].VIn = fine;  Field[1].VOut = size;
Field[1].XMin = anode_x0;  Field[1].XMax = anode_x1;
Field[1].YMin = 0;  Field[1].YMax = width;
Field[1].ZMin = height - fine;  Field[1].ZMax = y_bed + fine;
Field[1].Thickness = 0.2;
Field[2] = Box;
Field[2].VIn = fine;  Field[2].VOut = size;
Field[2].XMin = x0;  Field[2].XMax = half_length + paste_w;
Field[2].YMin = 0;  Field[2].YMax = slot_w + fine;
Field[2].ZMin = 0;  Field[2].ZMax = slot_h + fine;
Field[2].Thickness = 0.15;
Field[3] = Min;
Field[3].FieldsList = {1, 2};
Background Field = 3;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Mesh.MeshSizeMax = size;
