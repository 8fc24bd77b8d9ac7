"""World model v1, the paper-style latent video model (paper §3.2; docs/world_model.md, "World model v1").

A frame VAE (:mod:`.vae`) and the denoiser Ψ_θ (:mod:`.denoiser`, text conditioning in :mod:`.text`) trained
by flow matching (:mod:`.model`); presets in :mod:`.config`, per-task LoRA adapters in :mod:`.lora`, folders
in :mod:`.checkpoint`. Its torchrun trainer is :mod:`pilworld.world_model.training.trainer`. Not the default
(that is :mod:`pilworld.world_model.composite`); the benchmarks measure it.
"""
