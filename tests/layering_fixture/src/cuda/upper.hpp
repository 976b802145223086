// Fixture of the layering check: a cycle back through the file that includes this one.
#pragma once
#include "cuda/cycle.hpp"
