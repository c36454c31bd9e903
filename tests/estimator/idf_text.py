"""IDF text the reader's EnergyPlus comparison tests share."""

#: what every probe file starts with: one June day at Golden, a brick wall construction
HEADER = """
Version, 25.2;
SimulationControl, No, No, No, No, Yes, No, 1;
Timestep, 4;
Site:Location, Golden, 39.74, -105.18, -7.0, 1829.0;
RunPeriod, June, 6, 20, 2015, 6, 20, 2015, , No, No, No, Yes, Yes, No, Hour24;
Material, Brick, Rough, 0.2, 0.9, 1900, 800;
Construction, Wall, Brick;
"""

#: a 6 x 5 x 3 m brick box zone Z of rectangular surfaces: walls S, N, E, W, floor F, roof R
BOX = """
Zone, Z;
Wall:Exterior, S, Wall, Z, , 180, 90, 0, 0, 0, 6, 3;
Wall:Exterior, N, Wall, Z, , 0, 90, 6, 5, 0, 6, 3;
Wall:Exterior, E, Wall, Z, , 90, 90, 6, 0, 0, 5, 3;
Wall:Exterior, W, Wall, Z, , 270, 90, 0, 5, 0, 5, 3;
Floor:Adiabatic, F, Wall, Z, , 0, 180, 6, 0, 0, 6, 5;
Roof, R, Wall, Z, , 180, 0, 0, 0, 3, 6, 5;
"""
