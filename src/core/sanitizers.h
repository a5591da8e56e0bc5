// Which sanitizer this translation unit is built with, for the few places that must behave differently under one:
// HGS_SANITIZE_ADDRESS and HGS_SANITIZE_THREAD are 1 or 0. g++ defines __SANITIZE_ADDRESS__ / __SANITIZE_THREAD__;
// clang answers __has_feature(address_sanitizer) / __has_feature(thread_sanitizer) instead.
#pragma once

#if defined(__SANITIZE_ADDRESS__)
#define HGS_SANITIZE_ADDRESS 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define HGS_SANITIZE_ADDRESS 1
#endif
#endif
#ifndef HGS_SANITIZE_ADDRESS
#define HGS_SANITIZE_ADDRESS 0
#endif

#if defined(__SANITIZE_THREAD__)
#define HGS_SANITIZE_THREAD 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define HGS_SANITIZE_THREAD 1
#endif
#endif
#ifndef HGS_SANITIZE_THREAD
#define HGS_SANITIZE_THREAD 0
#endif
