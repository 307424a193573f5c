//! Vulkan runtime.
