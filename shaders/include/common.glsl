// Shared constants of ffls shaders.
const float PI = 3.14159265358979323846;
