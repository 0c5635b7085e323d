// Not valid gmsh syntax: the loader must say so and name this file.
Point(1) = {0, 0, 0;
