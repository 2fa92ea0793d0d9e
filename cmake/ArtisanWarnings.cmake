# One place for the project's compiler warnings; every target calls this.
function(artisan_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
                                           -Wcast-align -Woverloaded-virtual)
  # GCC 12 at -O2 reports false positives inside libstdc++ and Eigen (string concatenation,
  # GCC bug 105329; vector construction): these two are off.
  target_compile_options(${target} PRIVATE -Wno-restrict -Wno-stringop-overflow)
  if(ARTISAN_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()
