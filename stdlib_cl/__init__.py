# The OpenCL C library and ray-marching template, shipped as package data (fractalc.stdlib_cl).
