//! `stipple devices`: the GPU adapters and what they support.

use crate::Result;

pub fn devices() -> Result<()> {
    let list = stipple_render::gpu::list_adapters();
    if list.is_empty() {
        println!(
            "no GPU adapters found (on Linux without a GPU, install mesa-vulkan-drivers for the \
             lavapipe software adapter); rendering uses the CPU"
        );
        return Ok(());
    }
    for (i, a) in list.iter().enumerate() {
        println!("{i}: {} ({:?}, {:?})", a.name, a.backend, a.device_type);
        if !a.driver.is_empty() {
            println!("   driver: {}", a.driver);
        }
        println!(
            "   64-bit atomics: {}   timestamps: {}   max storage binding: {} MiB   max buffer: {} MiB",
            if a.int64_atomics { "yes (one-pass projection)" } else { "no (32-bit two-pass projection)" },
            if a.timestamps { "yes" } else { "no" },
            a.max_storage_binding >> 20,
            a.max_buffer >> 20
        );
        match &a.suitable {
            Ok(()) => println!("   usable by stipple: yes"),
            Err(why) => println!("   usable by stipple: no ({why})"),
        }
        if let Err(why) = &a.hardware_projection {
            println!(
                "   --projection hardware: unavailable ({why}); the default compute path runs"
            );
        }
    }
    match stipple_render::gpu::GpuContext::new(Default::default()) {
        Ok(c) => println!("--backend auto/gpu uses: {}", c.describe()),
        Err(e) => println!("--backend auto uses the CPU: {e}"),
    }
    Ok(())
}
