// Tests for the core; filled in below.
