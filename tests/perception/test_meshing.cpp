#include <gtest/gtest.h>
#include "artisan/perception/meshing.hpp"
TEST(Meshing, Placeholder) {}
