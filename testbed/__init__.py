"""A virtual building: EnergyPlus plays the real building."""
