//! STM32F405RG board layer (placeholder until the HAL bring-up lands below).
