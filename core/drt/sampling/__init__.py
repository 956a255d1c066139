"""Sample generators, warps and the pixel filter."""
