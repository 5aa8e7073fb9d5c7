"""Pixel-space V -> T generators: an RGB frame in, a tactile frame out, no latent features.

- `settings`: `Pix2PixSettings` and `PixelDDPMSettings` (config ``pixel.pix2pix``, ``pixel.ddpm``).
- `pix2pix`: the conditional GAN of Isola et al. 2017, scaled down (U-Net translator,
  PatchGAN discriminator, `fit_pix2pix`, `translate`).
- `ddpm`: a pixel U-Net DDPM with classifier-free guidance (`fit_pixel_ddpm`,
  `sample_pixel_ddpm`: DDIM with the latent generator's steps).
- `weights`: one hashed safetensors file per trained generator (`save_pixel_generator`,
  `load_pixel_generator`).

Frames are float32 NCHW arrays: RGB in [-1, 1]; tactile the background-subtracted clip128
frame as (x - 128) / 128, so no contact is exactly 0 and the range is [-1, 127/128].
"""
