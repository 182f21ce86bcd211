# The sweep's HTML report as a browser sees it: writes the report of RESULTS (a results.jsonl; when
# set, copied into OUT first) with `evio sweep --report`, or takes OUT's existing report, and runs
# check_html_report.py on OUT/report/index.html (headless Chromium: no broken image, no script error,
# self-contained, at least MIN_IMAGES images).
#   -DEVIO=... -DPYTHON=... -DCHECK=check_html_report.py -DOUT=DIR [-DRESULTS=file] -DMIN_IMAGES=N
# or, to test the check itself: -DPYTHON=... -DCHECK=... -DBROKEN=page.html (must fail, naming each fault).
if(BROKEN)  # the check itself: a page with a bad image, an outside file and a script error fails with each named
  execute_process(COMMAND ${PYTHON} ${CHECK} ${BROKEN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(rc EQUAL 77)
    message("SKIP: ${out}")
    return()
  endif()
  foreach(want "data is not a image/png" "broken image: not a png" "plots/missing.png> is not embedded"
          "script error: Uncaught ReferenceError: undefined_function_of_the_report")
    string(FIND "${out}" "${want}" at)
    if(at EQUAL -1)
      message(FATAL_ERROR "check_html_report.py did not report '${want}' (exit code ${rc}):\n${out}\n${err}")
    endif()
  endforeach()
  if(NOT rc EQUAL 1)
    message(FATAL_ERROR "check_html_report.py: exit code ${rc} on a broken page, expected 1\n${out}")
  endif()
  return()
endif()
execute_process(COMMAND ${PYTHON} -c "import matplotlib" RESULT_VARIABLE have)
if(NOT have EQUAL 0)
  message("SKIP: ${PYTHON} cannot import matplotlib (the report's plots)")
  return()
endif()
if(RESULTS)
  file(REMOVE_RECURSE ${OUT})
  file(MAKE_DIRECTORY ${OUT})
  configure_file(${RESULTS} ${OUT}/results.jsonl COPYONLY)
  execute_process(COMMAND ${EVIO} sweep --report ${OUT} --python ${PYTHON}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "evio sweep --report: exit code ${rc}\nstdout:\n${out}\nstderr:\n${err}")
  endif()
endif()
execute_process(COMMAND ${PYTHON} ${CHECK} ${OUT}/report/index.html --min-images ${MIN_IMAGES}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(rc EQUAL 77)
  message("SKIP: ${out}")
  return()
endif()
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "check_html_report.py: exit code ${rc}\n${out}\n${err}")
endif()
message("${out}")
