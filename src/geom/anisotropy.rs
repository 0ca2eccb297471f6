//! TODO(maps/sim issue): see issue text.
