"""Generate stage: a latent V->T diffusion generator (residual-MLP DDPM with classifier-free guidance)."""
