#pragma once
// Internal to lib/io: the pickle np.save writes for an object (used by npy.cpp).

#include <string>

#include "io/pickle.hpp"

namespace th::io::detail {

// pickle.dumps of a 0-d object ndarray holding `item`, as np.save(path, item) writes after the
// .npy header (protocol 3 there).
std::string pickle_object_array(const Value& item, int protocol);

}  // namespace th::io::detail
