//! Vulkan loader and instance, with optional Khronos validation whose messages are collected (not
//! printed) so tests can fail on any of them.

use anyhow::{Context, Result};
use ash::vk;
use std::ffi::{c_void, CStr};
use std::sync::{Arc, Mutex};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Messages reported by the validation layer (warnings and errors), shared with the callback.
pub type MessageLog = Arc<Mutex<Vec<String>>>;

/// Loader entry, instance and (when validation is on) the debug messenger.
pub struct Instance {
    /// Keeps libvulkan loaded for the instance's lifetime.
    _entry: ash::Entry,
    pub instance: ash::Instance,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    /// Keeps the callback's user data alive as long as the messenger.
    messages: MessageLog,
    callback_data: *mut MessageLog,
}

// The raw pointer is only the callback's user data (a boxed Arc), owned by this struct.
unsafe impl Send for Instance {}
unsafe impl Sync for Instance {}

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _ty: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) && !data.is_null()
        && !user.is_null()
    {
        let text = unsafe { (*data).message_as_c_str() }
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "<no message>".into());
        let log = unsafe { &*(user as *const MessageLog) };
        if let Ok(mut v) = log.lock() {
            v.push(format!("[{severity:?}] {text}"));
        }
    }
    vk::FALSE
}

impl Instance {
    /// Load libvulkan and create an instance (Vulkan 1.2). With `validation`, enable the Khronos
    /// layer when it is installed; `validation_active()` tells whether it was.
    pub fn new(validation: bool) -> Result<Instance> {
        let entry = unsafe { ash::Entry::load() }.context(
            "cannot load the Vulkan loader (libvulkan.so.1); install libvulkan1 and a driver, \
             e.g. `apt-get install libvulkan1 mesa-vulkan-drivers` for lavapipe",
        )?;
        let layer_present = unsafe { entry.enumerate_instance_layer_properties() }
            .unwrap_or_default()
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        let use_validation = validation && layer_present;
        let app = vk::ApplicationInfo::default()
            .application_name(c"alphasurf")
            .api_version(vk::API_VERSION_1_2);
        let layers = [VALIDATION_LAYER.as_ptr()];
        let exts = [ash::ext::debug_utils::NAME.as_ptr()];
        let mut info = vk::InstanceCreateInfo::default().application_info(&app);
        if use_validation {
            info = info
                .enabled_layer_names(&layers)
                .enabled_extension_names(&exts);
        }
        let instance = unsafe { entry.create_instance(&info, None) }
            .context("vkCreateInstance failed (is a Vulkan 1.2 driver installed?)")?;
        let messages: MessageLog = Arc::default();
        let callback_data = Box::into_raw(Box::new(messages.clone()));
        let debug = if use_validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let ci = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                        | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(on_message))
                .user_data(callback_data as *mut c_void);
            let m = unsafe { loader.create_debug_utils_messenger(&ci, None) }
                .context("creating the validation messenger")?;
            Some((loader, m))
        } else {
            None
        };
        Ok(Instance {
            _entry: entry,
            instance,
            debug,
            messages,
            callback_data,
        })
    }

    /// Whether the validation layer is running.
    pub fn validation_active(&self) -> bool {
        self.debug.is_some()
    }

    /// Validation messages collected so far.
    pub fn messages(&self) -> Vec<String> {
        self.messages.lock().map(|v| v.clone()).unwrap_or_default()
    }

    /// Physical devices in enumeration order.
    pub fn physical_devices(&self) -> Result<Vec<vk::PhysicalDevice>> {
        unsafe { self.instance.enumerate_physical_devices() }
            .context("vkEnumeratePhysicalDevices failed")
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        unsafe {
            if let Some((loader, m)) = self.debug.take() {
                loader.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
            drop(Box::from_raw(self.callback_data));
        }
    }
}
