// Fixture of the layering check: closes the cycle upper.hpp -> cycle.hpp -> upper.hpp.
#pragma once
#include "cuda/upper.hpp"
