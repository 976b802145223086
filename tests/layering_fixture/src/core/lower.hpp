// Fixture of the layering check (scripts/check_layers.py): core reaching up into cuda.
#pragma once
#include "cuda/upper.hpp"
